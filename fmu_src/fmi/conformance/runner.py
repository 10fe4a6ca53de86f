"""Every check on one FMU: the static ones here, each dynamic group in a child process of its own
with a time limit.  A child that dies (signal, abort, exit) or outlives its time fails the check
it was in, naming the signal and the last FMI call it made; the group then goes on in a new child
from the next check."""
from __future__ import annotations

import json
import signal
import subprocess
import sys

from fmu_src.fmi.conformance.checks import CHECKS, GROUPS, Result
from fmu_src.fmi.conformance.model import Fmu
from fmu_src.fmi.conformance.static import STATIC_CHECKS


def _death(returncode: int) -> str:
    if returncode < 0:
        try:
            return f"killed by signal {signal.Signals(-returncode).name}"
        except ValueError:
            return f"killed by signal {-returncode}"
    return f"exited with status {returncode}"


def run_group(fmu: Fmu, group: str, options: dict) -> list[Result]:
    ids = [c.id for c in CHECKS if c.group == group]
    results: list[Result] = []
    while len(results) < len(ids):
        first = ids[len(results)]
        proc = subprocess.Popen([sys.executable, "-m", "fmu_src.fmi.conformance.child", str(fmu.dir), group, first,
                                 json.dumps(options)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            out, err = proc.communicate(timeout=options["timeout"])
            death = None if proc.returncode == 0 else _death(proc.returncode)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
            death = f"no answer within the time limit of {options['timeout']:g} s (killed)"
        current, last_call = first, "no FMI call yet"
        for line in out.decode("utf-8", "replace").splitlines():
            try:
                message = json.loads(line)
            except json.JSONDecodeError:
                continue
            if "check" in message:
                current, last_call = message["check"], "no FMI call yet"
            elif "call" in message:
                last_call = message["call"]
            elif "result" in message:
                results.append(Result(**message["result"]))
        if death is not None and len(results) < len(ids):
            tail = err.decode("utf-8", "replace").strip().splitlines()[-3:]
            results.append(Result(current, "fail", f"the FMU's process {death} in {last_call}",
                                  {"last_call": last_call, "stderr_tail": tail}))
        elif death is None and len(results) < len(ids):
            results.append(Result(current, "fail", "the check process ended without a result"))
    return results


def run_all(fmu: Fmu, options: dict, only=()) -> list[Result]:
    """The result of every check, in the order of ``CHECKS``; ``only`` (check ids or group names)
    selects what runs, the rest is skipped as not selected (a group runs whole when any of its
    checks is selected: its checks share one process)."""
    def wanted(check):
        return not only or check.id in only or check.group in only

    found = {}
    for check in CHECKS:
        if check.group == "static" and wanted(check):
            problems = STATIC_CHECKS[check.id](fmu)
            found[check.id] = Result(check.id, "fail" if problems else "pass", "; ".join(problems),
                                     {"problems": len(problems)})
    for group in GROUPS[1:]:
        if any(wanted(c) for c in CHECKS if c.group == group):
            found.update((r.id, r) for r in run_group(fmu, group, options))
    return [found[c.id] if wanted(c) else Result(c.id, "skip", "not selected") for c in CHECKS]
