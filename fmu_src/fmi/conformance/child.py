"""The conformance child process: runs the dynamic checks of one group on one FMU, from a given
check on, and writes one JSON object a line on the protocol pipe (its original stdout; the FMU's
own writes to stdout go to stderr):

    {"check": ID}                      a check begins
    {"call": "fmi2DoStep(...)"}        before every FMI call
    {"result": {...}}                  a check's outcome (checks.Result.to_json)

    python -m fmu_src.fmi.conformance.child FMU_DIR GROUP FIRST_CHECK OPTIONS_JSON
"""
from __future__ import annotations

import json
import os
import sys
import traceback
from pathlib import Path

from fmu_src.fmi.conformance.capi import Binary
from fmu_src.fmi.conformance.checks import CHECKS, Result
from fmu_src.fmi.conformance.dynamic import DYNAMIC_CHECKS, Context, Failed, Skipped
from fmu_src.fmi.conformance.model import Fmu


def main(argv=None) -> int:
    folder, group, first, options = (argv or sys.argv[1:])[:4]
    pipe = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # what the FMU prints must not corrupt the protocol

    def send(obj):
        pipe.write(json.dumps(obj) + "\n")

    fmu = Fmu(Path(folder))
    ctx = None

    def trace(text):
        ctx.last_call = text
        send({"call": text})

    binary = Binary(fmu.library, fmu.version, fmu.md, fmu.dir / "resources", trace)
    ctx = Context(fmu, binary, json.loads(options))
    ids = [c.id for c in CHECKS if c.group == group]
    for check_id in ids[ids.index(first):]:
        send({"check": check_id})
        try:
            result = Result(check_id, "pass", details=DYNAMIC_CHECKS[check_id](ctx) or {})
        except Failed as exc:
            result = Result(check_id, "fail", str(exc))
        except Skipped as exc:
            result = Result(check_id, "skip", str(exc))
        except Exception as exc:  # a checker error is a failure with its cause, never a pass
            result = Result(check_id, "fail", f"checker error after {ctx.last_call or 'no call'}: {exc!r}",
                            {"traceback": traceback.format_exc(limit=3)})
        binary.log.clear()
        send({"result": result.to_json()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
