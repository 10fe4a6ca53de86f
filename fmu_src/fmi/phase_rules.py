"""Which FMI function may be called in which state: one table for every FMU of the project.

The FMI 2.0 co-simulation state machine (FMI 2.0.4 section 4.2.4, the table of allowed calls)
and the FMI 3.0 co-simulation state machine without event mode (FMI 3.0 section 4.3), restricted
to the states the project's FMUs can be in.  The C guard of the pythonfmu FMUs, the native
regulator and CommandSource FMUs take their masks from the header :func:`c_header` generates
(``fmi_phase_rules.h``, written by the build beside their sources), and the pythonfmu slave base
(``avr_slavebase.py``) takes its phase sets from :data:`FMI2_ALLOWED`.

States the FMUs never enter are left out: ``stepCanceled``/``stepPending`` (no asynchronous
steps), ``error``/``fatal`` (a refused call changes nothing; the guard's own fatal state
admits only fmi2FreeInstance), and FMI 3.0's Configuration, Reconfiguration, Event,
Intermediate Update and Step Discarded modes (none of them is supported).  ``stepFailed``
occurs only in the guard (an inner doStep that answered Discard or Error).

A function an FMU does not provide (its model description says so) is refused in every state
whatever this table says; this table is what the standard allows.
"""
from __future__ import annotations

#: The states, in the order of their bit in the C masks (bit i = 1 << i): FMI 2.0 name, FMI 3.0 name.
#: The native FMUs store the bit in their FMU-state blobs, so the order is part of that format.
PHASES = (("instantiated", "Instantiated"), ("initializationMode", "InitializationMode"),
          ("stepComplete", "StepMode"), ("terminated", "Terminated"), ("stepFailed", None))
FMI2_PHASES = tuple(fmi2 for fmi2, _ in PHASES)
FMI3_PHASES = tuple(fmi3 for _, fmi3 in PHASES if fmi3 is not None)
_C_NAMES = ("FMI_INSTANTIATED", "FMI_INIT_MODE", "FMI_STEP_MODE", "FMI_TERMINATED", "FMI_STEP_FAILED")

_I2, _INIT2, _STEP2, _TERM2, _FAILED2 = FMI2_PHASES
_ANY2 = frozenset(FMI2_PHASES)
_GET2 = frozenset({_INIT2, _STEP2, _FAILED2, _TERM2})
_SET2 = frozenset({_I2, _INIT2, _STEP2})
_STATUS2 = frozenset({_STEP2, _FAILED2, _TERM2})

#: FMI 2.0 co-simulation: function -> the states it may be called in (section 4.2.4).
FMI2_ALLOWED: dict[str, frozenset[str]] = {
    "fmi2SetDebugLogging": _ANY2,
    "fmi2SetupExperiment": frozenset({_I2}),
    "fmi2EnterInitializationMode": frozenset({_I2}),
    "fmi2ExitInitializationMode": frozenset({_INIT2}),
    "fmi2Terminate": frozenset({_STEP2, _FAILED2}),
    "fmi2Reset": _ANY2,
    **{f"fmi2Get{t}": _GET2 for t in ("Real", "Integer", "Boolean", "String")},
    **{f"fmi2Set{t}": _SET2 for t in ("Real", "Integer", "Boolean", "String")},
    **{f"fmi2{f}": _ANY2 for f in ("GetFMUstate", "SetFMUstate", "FreeFMUstate", "SerializedFMUstateSize",
                                   "SerializeFMUstate", "DeSerializeFMUstate")},
    "fmi2GetDirectionalDerivative": _GET2,
    "fmi2SetRealInputDerivatives": _SET2,
    "fmi2GetRealOutputDerivatives": _STATUS2,
    "fmi2DoStep": frozenset({_STEP2}),
    "fmi2CancelStep": frozenset(),  # stepPending only: never entered
    **{f"fmi2Get{t}Status": _STATUS2 for t in ("", "Real", "Integer", "Boolean", "String")},
}

_I3, _INIT3, _STEP3, _TERM3 = FMI3_PHASES
_ANY3 = frozenset(FMI3_PHASES)
_GET3 = frozenset({_INIT3, _STEP3, _TERM3})
_SET3 = frozenset({_I3, _INIT3, _STEP3})
_TYPES3 = ("Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64",
           "Boolean", "String", "Binary")

#: FMI 3.0 co-simulation without event mode: function -> the states it may be called in (section 4.3).
#: Functions allowed only in states this FMU never enters (event, configuration, Model Exchange and
#: Scheduled Execution modes) have no state here.
FMI3_ALLOWED: dict[str, frozenset[str]] = {
    "fmi3SetDebugLogging": _ANY3,
    "fmi3EnterInitializationMode": frozenset({_I3}),
    "fmi3ExitInitializationMode": frozenset({_INIT3}),
    "fmi3Terminate": frozenset({_STEP3}),
    "fmi3Reset": _ANY3,
    **{f"fmi3Get{t}": _GET3 for t in _TYPES3},
    **{f"fmi3Set{t}": _SET3 for t in _TYPES3},
    **{f"fmi3{f}": _ANY3 for f in ("GetFMUState", "SetFMUState", "FreeFMUState", "SerializedFMUStateSize",
                                   "SerializeFMUState", "DeserializeFMUState")},
    "fmi3EnterConfigurationMode": frozenset({_I3, _STEP3}),
    "fmi3ExitConfigurationMode": frozenset(),
    "fmi3GetClock": frozenset(),
    "fmi3SetClock": frozenset(),
    "fmi3GetNumberOfVariableDependencies": frozenset({_I3, _INIT3, _STEP3, _TERM3}),
    "fmi3GetVariableDependencies": frozenset({_I3, _INIT3, _STEP3, _TERM3}),
    "fmi3GetDirectionalDerivative": frozenset({_INIT3, _STEP3, _TERM3}),
    "fmi3GetAdjointDerivative": frozenset({_INIT3, _STEP3, _TERM3}),
    "fmi3GetOutputDerivatives": frozenset({_STEP3, _TERM3}),
    "fmi3EnterEventMode": frozenset({_STEP3}),
    "fmi3EnterStepMode": frozenset(),
    "fmi3DoStep": frozenset({_STEP3}),
}


def c_bits(phases) -> str:
    """The C mask of ``phases`` (FMI 2.0 or 3.0 names) as an expression of the FMI_* bits."""
    names = [c for c, (fmi2, fmi3) in zip(_C_NAMES, PHASES) if fmi2 in phases or fmi3 in phases]
    return "(" + " | ".join(names) + ")" if names else "0u"


def c_header() -> str:
    """The text of ``fmi_phase_rules.h``: one bit per state and one ``FMI_MASK_<function>`` per function."""
    lines = ["/* Generated by build.py from fmu_src/fmi/phase_rules.py (the FMI 2.0 and 3.0 co-simulation",
             " * state machines): do not edit. */",
             "#ifndef FMI_PHASE_RULES_H", "#define FMI_PHASE_RULES_H", "",
             "/* One bit per state (FMI 2.0 name / FMI 3.0 name). */"]
    lines += [f"#define {c} (1u << {bit})  /* {fmi2} / {fmi3 or '-'} */"
              for bit, (c, (fmi2, fmi3)) in enumerate(zip(_C_NAMES, PHASES))]
    lines += [f"#define FMI_N_PHASES {len(PHASES)}", f"#define FMI_ANY_PHASE {c_bits(FMI2_PHASES)}", "",
              "#if defined(__GNUC__)", "#define FMI_MAYBE_UNUSED __attribute__((unused))", "#else",
              "#define FMI_MAYBE_UNUSED", "#endif",
              "/* The states' names in each version's words, indexed by bit number. */",
              "static const char *const FMI2_PHASE_NAMES[] FMI_MAYBE_UNUSED = {"
              + ", ".join(f'"{p}"' for p in FMI2_PHASES) + "};",
              "static const char *const FMI3_PHASE_NAMES[] FMI_MAYBE_UNUSED = {"
              + ", ".join(f'"{p}"' for p in FMI3_PHASES) + "};", "",
              "/* The states each function may be called in. */"]
    for table in (FMI2_ALLOWED, FMI3_ALLOWED):
        lines += [f"#define FMI_MASK_{fn} {c_bits(phases)}" for fn, phases in table.items()]
    return "\n".join([*lines, "", "#endif", ""])
