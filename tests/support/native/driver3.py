"""tests/support/fmi/driver.py for FMI 3.0 FMUs: the same call vocabulary and JSON protocol.

    python driver3.py FMU_PATH            # JSON lines on stdin -> JSON lines on stdout
    python driver3.py FMU_PATH CALLS_JSON # one sequence, prints one JSON list

FMI 3.0 has no fmi3SetupExperiment: ``["setup", t0]`` only records the start time that
the next ``["enter"]`` passes to fmi3EnterInitializationMode (so it is answered OK
without reaching the FMU; the FMI 3.0 call-sequence model never sends it).
"""
import sys
from pathlib import Path

from fmpy.fmi3 import FMU3Slave

sys.path.insert(0, str(Path(__file__).parents[1] / "fmi"))
from driver import Driver, main  # noqa: E402  (tests/support/fmi/driver.py)

#: The FMU state methods the FMI 2.0 driver calls, spelled as FMI 3.0 spells them.
FMU_STATE_NAMES = {"getFMUstate": "getFMUState", "setFMUstate": "setFMUState",
                   "serializeFMUstate": "serializeFMUState", "deSerializeFMUstate": "deserializeFMUState"}
TYPED = {"Float64": ("getFloat64", "setFloat64"), "Int32": ("getInt32", "setInt32"),
         "Boolean": ("getBoolean", "setBoolean")}


class Driver3(Driver):
    slave_class = FMU3Slave
    start_time = 0.0

    def _instantiate(self):
        answer = super()._instantiate()
        if self.fmu is not None:
            for fmi2_name, fmi3_name in FMU_STATE_NAMES.items():
                setattr(self.fmu, fmi2_name, getattr(self.fmu, fmi3_name))
        return answer

    def _call(self, op, *args):
        fmu = self.fmu
        if op == "setup":
            self.start_time = args[0]
        elif op == "enter":
            fmu.enterInitializationMode(startTime=self.start_time)
        elif op in ("set", "get"):
            var = self.vars[args[0]]
            getter, setter = TYPED[var.type]
            if op == "set":
                getattr(fmu, setter)([var.valueReference], [args[1]])
                return None
            return {"value": getattr(fmu, getter)([var.valueReference])[0]}
        else:  # instantiate, exit, step, terminate, reset, free and the FMU state ops: the FMI 2.0 driver's
            return super()._call(op, *args)
        return None


if __name__ == "__main__":
    main(Driver3)
