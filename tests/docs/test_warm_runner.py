"""support.warm.run gives what subprocess.run of a new interpreter gives (the FMI drivers' crash
isolation rests on it): output, stdin, arguments, folder, environment, exit codes, signals,
uncaught exceptions and time limits; and each child starts from the server's state, not from
an earlier child's."""
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from support import warm

SCRIPT = """
import json, os, sys
import fmpy
cmd = sys.argv[1]
seen = getattr(fmpy, "_warm_mark", None)
fmpy._warm_mark = cmd                        # what a later child must not see
print(json.dumps({"args": sys.argv[1:], "cwd": os.getcwd(), "stdin": sys.stdin.read(), "name": __name__,
                  "env": os.environ.get("WARM_TEST"), "path0": sys.path[0], "seen": seen}))
sys.stdout.flush()
print("to stderr", file=sys.stderr)
if cmd == "exit":
    sys.exit(7)
if cmd == "message":
    sys.exit("a message")
if cmd == "raise":
    raise ValueError("uncaught")
if cmd == "segv":
    import ctypes
    ctypes.string_at(0)
if cmd == "abort":
    os.abort()
if cmd == "hang":
    import time
    time.sleep(60)
"""

pytestmark = pytest.mark.skipif(not warm.AVAILABLE, reason="the warm server forks: Linux only")


@pytest.fixture
def script(tmp_path):
    path = tmp_path / "bin" / "probe.py"
    path.parent.mkdir()
    path.write_text(SCRIPT)
    return path


def _new_interpreter(script, args, **kw):
    return subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True, **kw)


@pytest.mark.parametrize("cmd", ["ok", "exit", "message", "raise", "segv", "abort"])
def test_a_forked_run_gives_what_a_new_interpreter_gives(script, tmp_path, monkeypatch, cmd):
    monkeypatch.setenv("WARM_TEST", "from the caller")  # set after the server may have started
    warm_run = warm.run(script, [cmd, 2], input="some input", cwd=tmp_path)
    new = _new_interpreter(script, [cmd, "2"], input="some input", cwd=tmp_path)
    assert warm_run.returncode == new.returncode
    assert warm_run.stdout == new.stdout
    # the traceback's first frame differs (runpy's), its end does not
    assert warm_run.stderr.splitlines()[-1:] == new.stderr.splitlines()[-1:]
    answer = json.loads(warm_run.stdout.splitlines()[0])
    assert answer == {"args": [cmd, "2"], "cwd": str(tmp_path), "stdin": "some input", "name": "__main__",
                      "env": "from the caller", "path0": str(script.parent), "seen": None}
    if cmd in ("segv", "abort"):
        assert warm_run.returncode == -(signal.SIGSEGV if cmd == "segv" else signal.SIGABRT)


def test_each_child_starts_from_the_server_not_from_an_earlier_child(script):
    first, second = (json.loads(warm.run(script, [name]).stdout.splitlines()[0]) for name in ("first", "second"))
    assert first["seen"] is None and second["seen"] is None


def test_a_run_over_its_time_limit_is_killed_and_raises_as_subprocess_does(script):
    with pytest.raises(subprocess.TimeoutExpired) as err:
        warm.run(script, ["hang"], timeout=1.0)
    assert json.loads(err.value.output.splitlines()[0])["args"] == ["hang"]
    assert warm.run(script, ["ok"]).returncode == 0  # the server goes on


def test_a_changed_start_up_environment_gets_a_new_interpreter(tmp_path):
    probe = tmp_path / "ppid.py"
    probe.write_text("import os; print(os.getppid())")
    assert int(warm.run(probe).stdout) != os.getpid()  # forked by the server
    env = dict(os.environ, PYTHONHASHSEED="123")
    assert int(warm.run(probe, env=env).stdout) == os.getpid()  # read at start-up: a new interpreter


def test_a_dead_server_is_replaced_and_a_run_it_took_down_fails_loudly(tmp_path):
    probe = tmp_path / "ppid.py"
    probe.write_text("import os, sys, time\nprint(os.getppid(), flush=True)\nif sys.argv[1:] == ['wait']: time.sleep(60)\n")
    server = int(warm.run(probe).stdout)
    os.kill(server, signal.SIGKILL)
    _wait_dead(server)
    again = int(warm.run(probe).stdout)
    assert again not in (server, os.getpid())  # a new server forked it
    # the server dies while a child runs: that run fails naming the server, the next one works
    threading.Timer(1.0, os.kill, (again, signal.SIGKILL)).start()
    with pytest.raises(RuntimeError, match="warm server .* died"):
        warm.run(probe, ["wait"], timeout=30)
    assert int(warm.run(probe).stdout) not in (again, os.getpid())


def _wait_dead(pid: int) -> None:
    """Until ``pid`` (a child of this process, which warm reaps) is a zombie or gone."""
    stat = Path(f"/proc/{pid}/stat")
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            if stat.read_text().rsplit(")", 1)[1].split()[0] in ("Z", "X"):
                return
        except (FileNotFoundError, ProcessLookupError):
            return
        time.sleep(0.01)
    raise AssertionError(f"process {pid} did not die")
