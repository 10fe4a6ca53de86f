"""A dynamic FMI 2.0/3.0 co-simulation conformance check for any FMU:

    python -m fmu_src.fmi.conformance PATH.fmu [--report junit.xml] [--json out.json]

the model description (schema, variables, start ranges, model structure, units), every FMI
function in every state of the state machine (``fmu_src/fmi/phase_rules.py``), argument and
FMU-state fuzzing, and the life cycle; each dynamic check group runs in a child process with a
time limit, so a crash or hang of the FMU fails that check with its signal and last call.  The
checks and their sections of the standard: ``checks.py``; docs/conformance.md."""
