"""The checks: their names, groups, what each enforces and the section of the standard it
enforces, in the order they run.  A group's checks run in one process (the static group in the
checker's own: it reads XML only, no FMU code runs); a check that crashes or hangs its process
fails, and the group goes on in a new process with the next check."""
from __future__ import annotations

from dataclasses import dataclass, field

FMI2 = "FMI 2.0.4"
FMI3 = "FMI 3.0"


@dataclass(frozen=True)
class Check:
    id: str
    title: str
    sections: dict  # FMI version -> "standard, section"

    @property
    def group(self) -> str:
        return self.id.split(".")[0]

    def section(self, version: int) -> str:
        return self.sections[version]


def _check(id, title, fmi2, fmi3):
    return Check(id, title, {2: f"{FMI2} {fmi2}", 3: f"{FMI3} {fmi3}"})


CHECKS = (
    _check("static.schema", "modelDescription.xml valid against the official XSD",
           "2.2 (fmi2ModelDescription.xsd)", "'FMI Description Schema' (fmi3ModelDescription.xsd)"),
    _check("static.variables", "legal causality/variability/initial combinations; start given where required, "
           "absent where forbidden", "2.2.7 (causality/variability and initial tables)",
           "'Model Variables' (causality, variability, initial)"),
    _check("static.start_range", "start values within [min, max]", "2.2.7 (min <= start <= max)",
           "'Model Variables' (min <= start <= max)"),
    _check("static.model_structure", "every output listed once in the model structure, every initial unknown "
           "listed, dependencies valid", "2.2.8 (ModelStructure)", "'Model Structure'"),
    _check("static.units", "every unit and display unit used is declared", "2.2.2 (UnitDefinitions)",
           "'Unit Definitions'"),
    _check("machine.legal_calls", "every function in every state that allows it, with valid arguments: "
           "no Error or Fatal", "4.2.4 (state machine of co-simulation)", "'State Machine for Co-Simulation'"),
    _check("machine.illegal_calls", "every function in every state that does not allow it: Error, "
           "never OK, never a crash", "4.2.4 (state machine of co-simulation)", "'State Machine for Co-Simulation'"),
    _check("machine.error_state", "after an Error: getting values works, a state saved before restores and goes "
           "on like no Error happened, and after fmiReset the instance runs like a new one",
           "2.1.3 (fmi2Error) and 4.2.4", "'Status Returned by Functions' (fmi3Error) and 'State Machine for "
           "Co-Simulation'"),
    _check("arguments.instantiate", "wrong, empty or NULL GUID/instantiation token and wrong FMU type refused "
           "(NULL), never a crash", "2.1.5 (fmi2Instantiate)", "'Creation, Destruction and Logging of FMU Instances' (fmi3InstantiateCoSimulation)"),
    _check("arguments.null_callbacks", "NULL callbacks (FMI 2.0 functions, FMI 3.0 logMessage) never crash "
           "the FMU", "2.1.5 (fmi2CallbackFunctions)", "'Creation, Destruction and Logging of FMU Instances' (logMessage may be NULL)"),
    _check("arguments.null_arrays", "NULL value-reference and value arrays with nvr > 0 and NULL FMU-state "
           "pointers refused, never a crash", "2.1.7 (fmi2GetXXX/fmi2SetXXX)", "'Getting and Setting Variable Values'"),
    _check("arguments.unknown_vr", "value references the model description does not define refused",
           "2.1.7 (fmi2GetXXX/fmi2SetXXX)", "'Getting and Setting Variable Values'"),
    _check("arguments.out_of_range", "values one step outside [min, max] (and NaN): refused (Discard/Error) or "
           "handled, never Fatal or a crash; the instance goes on", "2.2.7 (min/max) and 2.1.7",
           "2.2.6.3 (Handling min/max Range Violations)"),
    _check("arguments.step_size", "negative, non-finite and huge communication steps: never a crash or hang; "
           "negative and non-finite refused; the instance steps on", "4.2.2 (fmi2DoStep)", "'Computation in Step Mode' (fmi3DoStep)"),
    _check("state.restore", "get the FMU state, step, restore, step: identical outputs",
           "2.1.8 (fmi2GetFMUstate/fmi2SetFMUstate)", "'Getting and Setting the Complete FMU State'"),
    _check("state.serialize", "serialize, deserialize, serialize: identical bytes, identical outputs",
           "2.1.8 (fmi2SerializeFMUstate/fmi2DeSerializeFMUstate)",
           "'Getting and Setting the Complete FMU State'"),
    _check("state.tampered", "bit flips, truncations and foreign bytes in a serialized state refused with "
           "Error, or, if accepted, equal to the untampered restore", "2.1.8 (fmi2DeSerializeFMUstate)",
           "'Getting and Setting the Complete FMU State' (fmi3DeserializeFMUState)"),
    _check("lifecycle.memory", "instantiate/free cycles: resident memory growth within the bound",
           "2.1.5 (fmi2FreeInstance)", "'Creation, Destruction and Logging of FMU Instances' (fmi3FreeInstance)"),
    _check("lifecycle.independence", "a second instance with other inputs does not change the first's outputs",
           "2.1.5 (instances are independent)", "'Creation, Destruction and Logging of FMU Instances' (instances are independent)"),
    _check("lifecycle.reset", "after fmiReset a run gives the outputs of a new instance", "2.1.6 (fmi2Reset)",
           "'Initialization, Termination, and Resetting an FMU' (fmi3Reset)"),
    _check("lifecycle.determinism", "two runs with the same inputs give the same bits",
           "4.2.2 (doStep on the same state and inputs; reproducibility, not a normative rule)",
           "'Computation in Step Mode' (reproducibility, not a normative rule)"),
)
BY_ID = {c.id: c for c in CHECKS}
GROUPS = tuple(dict.fromkeys(c.group for c in CHECKS))


@dataclass
class Result:
    """One check's outcome: ``status`` "pass", "fail" or "skip"; ``message`` the reason (the
    failing call and its arguments for a failure); ``details`` what was measured."""

    id: str
    status: str
    message: str = ""
    details: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"id": self.id, "status": self.status, "message": self.message, "details": self.details}
