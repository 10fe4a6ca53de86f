"""The server behind :mod:`support.warm`: imports fmpy once, then forks one child per request
and runs a support script in it as ``python SCRIPT ARGS`` would.

    python warm_server.py        # JSON lines on stdin -> JSON lines on stdout

It answers ``{"ready": pid}`` once its imports are done, then one line per request
``{"script", "args", "cwd", "env", "input", "timeout"}``:
``{"exit": code, "stdout": text, "stderr": text, "timed_out": bool}`` (``exit`` negative:
killed by that signal; text decoded with ``surrogateescape``, so no byte is lost). A child
that outlives ``timeout`` is killed (SIGKILL) and reported as timed out. The server ends when
its stdin closes; each child dies with it (Linux ``PR_SET_PDEATHSIG``).

The server imports what the scripts share (fmpy and its dependencies) and nothing of the tests: it
never loads an FMU, so every child starts from the same state a new interpreter reaches
after those imports.
"""
import importlib
import json
import os
import runpy
import selectors
import signal
import sys
import time
import traceback

from scenarios.campaign.forkrun import die_with_parent  # the campaigns' fork server's: Linux PR_SET_PDEATHSIG

#: What the server imports before its first fork: what every support script imports.
PRELOAD = ("numpy", "fmpy", "fmpy.fmi1", "fmpy.fmi2", "fmpy.fmi3", "fmpy.logging", "fmpy.model_description")


def _child(request, fds, server_pid):
    """In the forked child: become ``python SCRIPT ARGS`` and exit (never returns)."""
    code = 1
    try:
        die_with_parent()
        if os.getppid() != server_pid:  # the server died before the line above
            os._exit(1)
        for fd, target in zip((0, 1, 2), fds):
            os.dup2(target, fd)
        os.closerange(3, 256)  # the protocol pipe and the other ends: not the script's
        # fresh standard streams: the server's sys.stdin may hold protocol lines read ahead
        sys.stdin = sys.__stdin__ = open(0, "r", closefd=False)
        sys.stdout = sys.__stdout__ = open(1, "w", closefd=False)
        sys.stderr = sys.__stderr__ = open(2, "w", buffering=1, errors="backslashreplace", closefd=False)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        os.chdir(request["cwd"])
        os.environ.clear()
        os.environ.update(request["env"])
        script = request["script"]
        sys.argv = [script, *request["args"]]
        sys.path[0] = os.path.dirname(os.path.abspath(script))
        runpy.run_path(script, run_name="__main__")
        code = 0
    except SystemExit as exc:
        if exc.code is None or isinstance(exc.code, int):
            code = exc.code or 0
        else:
            print(exc.code, file=sys.stderr)
            code = 1
    except BaseException:  # what the interpreter prints for an uncaught exception, exit 1
        traceback.print_exc()
        code = 1
    try:
        import atexit

        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
    except BaseException:
        pass
    os._exit(code)


def serve(request):
    """Fork a child for ``request``, feed its stdin, collect its output, wait for it."""
    pipes = [os.pipe() for _ in range(3)]  # (read, write) for stdin, stdout, stderr
    child_fds = (pipes[0][0], pipes[1][1], pipes[2][1])
    server_pid = os.getpid()
    pid = os.fork()
    if pid == 0:
        _child(request, child_fds, server_pid)
    for fd in child_fds:
        os.close(fd)
    stdin, stdout, stderr = pipes[0][1], pipes[1][0], pipes[2][0]
    data = (request.get("input") or "").encode("utf-8", "surrogateescape")
    out = {stdout: bytearray(), stderr: bytearray()}
    sel = selectors.DefaultSelector()
    if data:
        os.set_blocking(stdin, False)
        sel.register(stdin, selectors.EVENT_WRITE)
    else:
        os.close(stdin)
    for fd in out:
        sel.register(fd, selectors.EVENT_READ)
    timeout = request.get("timeout")
    deadline = None if timeout is None else time.monotonic() + timeout
    timed_out = False
    while sel.get_map():
        wait = None if deadline is None or timed_out else max(0.0, deadline - time.monotonic())
        events = sel.select(wait)
        if not events and not timed_out and deadline is not None and time.monotonic() >= deadline:
            os.kill(pid, signal.SIGKILL)
            timed_out = True
            continue
        for key, _ in events:
            fd = key.fd
            if fd == stdin:
                try:
                    data = data[os.write(fd, data[:65536]):]
                except BrokenPipeError:
                    data = b""
                if not data:
                    sel.unregister(fd)
                    os.close(fd)
            else:
                chunk = os.read(fd, 65536)
                if chunk:
                    out[fd] += chunk
                else:
                    sel.unregister(fd)
                    os.close(fd)
    sel.close()
    _, status = os.waitpid(pid, 0)
    return {"exit": os.waitstatus_to_exitcode(status), "timed_out": timed_out,
            "stdout": out[stdout].decode("utf-8", "surrogateescape"),
            "stderr": out[stderr].decode("utf-8", "surrogateescape")}


def main():
    for name in PRELOAD:
        importlib.import_module(name)
    protocol = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # whatever else writes to stdout must not corrupt the protocol
    sys.stdout.flush()
    sys.stderr.flush()
    protocol.write(json.dumps({"ready": os.getpid()}) + "\n")
    for line in sys.stdin:
        protocol.write(json.dumps(serve(json.loads(line))) + "\n")


if __name__ == "__main__":
    main()
