"""The pythonfmu FMUs' documentation pages (``documentation/index.html``); the regulator's
method section is ``docs/method.md`` rendered."""
from __future__ import annotations

from fmu_src.packing.describe import variables_table
from fmu_src.packing.method_page import method_html
from fmu_src.packing.parameters import parameters_html


def regulator_page(model_identifier: str, specs) -> str:
    """The AdaptiveVelocityRegulator FMU's page: the method, its FMI behaviour, the variables."""
    return f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>{model_identifier}</title></head><body>
<h1>{model_identifier}</h1>
{method_html()}<h2>FMI behaviour</h2>
<p>Co-simulation, any communication step &gt; 0 (one regulator call per step whatever its length: no
maximum; a step whose end time overflows is refused). Calls the FMI 2.0 state machine forbids, sets of outputs or of
fixed parameters after initialization, NaN/inf values and values outside [min, max] are refused with
fmi2Error and a log message naming the variable and its range; a refused call changes nothing. The six offsets
are clipped to &plusmn;<code>delta_limit_rad</code>. FMU state can be saved, restored and serialized (all weights
and memories); a serialized state carries a CRC-64, the FMU's GUID and the fixed parameters' values, and a
corrupted, truncated, foreign or non-finite state, or one saved with other fixed parameters, is refused with
fmi2Error naming why; so is a state whose checksums are right but whose contents no run can reach (header and
contents disagreeing on the phase or time, a value outside its range, counters beyond what a run counts).
Requires Python 3 with numpy in the host process
(see <code>resources/requirements.txt</code>).</p>
{parameters_html()}{variables_table(specs)}"""


def plant_page(model_identifier: str, plant_lib: str, specs) -> str:
    """The CassiePlant FMU's page: the plant, its FMI behaviour, the variables."""
    from fmu_src.plant_fmu.fmu_core import MAX_STEP_S, PLANT_STEP_S

    return f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>{model_identifier}</title></head><body>
<h1>{model_identifier}</h1>
<p>MuJoCo Cassie biped (Menagerie's agility_cassie or Oregon State's model, both in
<code>resources/{plant_lib}/models</code> with their licenses) with a nominal HZD-style walking controller:
0.5 ms plant step, joint PD servos inside MuJoCo, starts from rest in the standing pose, stands, shifts its
weight and walks at the commanded speed. Connect the AdaptiveVelocityRegulator FMU name to name: this FMU's
outputs vx, vy, pitch, roll, pitch_rate, roll_rate, step_index are its inputs, its six delta_* outputs are
this FMU's inputs.</p>
<h2>FMI behaviour</h2>
<p>Co-simulation; communication steps must be whole multiples of {PLANT_STEP_S * 1e3:g} ms and at most
{MAX_STEP_S:g} s, the maximum communication step (else fmi2Error naming the step and the rule): one doStep runs
its plant steps to the end and cannot be interrupted, so a longer one, which could run for hours, is refused
and a master takes several steps.
A fall sets the output <code>fell</code>; the simulation goes on. Calls the state machine forbids, sets of
outputs or of fixed parameters after initialization, NaN/inf or out-of-range values: fmi2Error, logged,
no effect. Invalid parameter combinations (the plant's own validation, every problem named with its range)
make fmi2ExitInitializationMode return fmi2Error and stay in initialization mode. FMU state: MuJoCo's full
integration state and the controller's memory; restore-then-continue is bit-identical. A state is checked for
meaning as well as integrity: header and contents agree on the phase and time, every number is finite and
within MuJoCo's bound (1e10), quaternions have unit norm, the controller's mode and stance are known ones, its
step times precede the simulated time, and the command and offsets lie within the inputs' ranges; otherwise
fmi2Error naming the field. Needs Python 3 with
numpy and mujoco in the host (<code>resources/requirements.txt</code>); linux64.</p>
{variables_table(specs)}"""
