"""``python -m scenarios export-ssp SCENARIO``: a suite scenario as a standard SSP.

The SSP holds the plant (``CassiePlant.fmu``), the regulator
(``AdaptiveVelocityRegulator.fmu``) and a copy of the command source
(``CommandSource_fmi2.fmu``) whose ``resources/schedule.csv`` is the scenario's command
schedule and pushes (:func:`schedule_rows`); the wiring and parameter sets are
:mod:`scenarios.ssp.system`'s.  Parameter sets bind only parameters: the plant's (the
scenario's model and perturbation, as ``--plant fmu`` sets them) and the regulator's
(the arm's configuration: ``[regulator]`` and the arm's overrides, its ``seed`` included, e.g.
``adaptation_enabled = false`` for ``pd_only``; with ``--profile NAME`` on top of that profile's
values, as ``run --profile`` does).  One SSP per arm: an SSP has one
regulator configuration; ``--arm`` picks it (default: the scenario's first arm).
Its default experiment is the scenario's duration with its 5 ms step.

Refused, naming why (exit 2): an arm that is not the regulator (``rl_hzd``: the
RL-HZD policy runs in-process only), a model given as an MJCF path (the plant FMU
holds the built-in models only), terrain with a flat start patch other than the
plant's default (the plant FMU has no parameter for it), a communication step other
than the system's 5 ms.

Switching instants are our master's: the command of step k is
``scenario.command_at_step(k)``, a push acts over the steps ``[k0, k0 + kd)``; the
schedule has a row at ``k * h`` wherever either changes.
"""
from __future__ import annotations

import logging
import tempfile
from pathlib import Path

from scenarios.ssp import system

log = logging.getLogger(__name__)

#: The command source's outputs, in its schedule's column order.
SCHEDULED = ("vx_des", "vy_des", "yaw_rate_des", "push_fx", "push_fy", "push_fz")


class NotExpressible(ValueError):
    """The scenario (or arm) needs something the SSP's FMUs cannot hold; ``problems`` say what."""

    def __init__(self, problems: list[str]):
        super().__init__("; ".join(problems))
        self.problems = problems


def schedule_rows(scenario) -> list[tuple[float, dict[str, float]]]:
    """(time, values of :data:`SCHEDULED`) at t = 0 and wherever the scenario's command or
    push changes, on its communication grid (time k * h)."""
    out, last = [], None
    for k in range(scenario.n_comm_steps):
        now = dict(zip(SCHEDULED, (*scenario.command_at_step(k), *scenario.push_force_at_step(k))))
        if now != last:
            out.append((k * scenario.comm_step_s, now))
            last = now
    return out


def problems(scenario, arm_name: str) -> list[str]:
    """Why ``scenario``'s arm ``arm_name`` cannot be an SSP of the three FMUs (empty: it can)."""
    from fmu_src.plant_fmu.fmu_core import MODEL_FILES
    from scenarios.lang.scenario import DEFAULT_FLAT_RADIUS_M

    found = []
    names = [a.name for a in scenario.arms]
    if arm_name not in names:
        return [f"--arm {arm_name}: scenario {scenario.name} has the arms {', '.join(names)}"]
    arm = scenario.arm(arm_name)
    if arm.controller != "regulator":
        found.append(f"arm {arm_name}: its controller is {arm.controller} (the RL-HZD policy runs in-process only; "
                     "it is no FMU)")
    if scenario.model not in MODEL_FILES:
        found.append(f"model = {scenario.model!r}: the CassiePlant FMU holds {', '.join(MODEL_FILES)} only")
    if scenario.terrain is not None and scenario.terrain.flat_radius_m != DEFAULT_FLAT_RADIUS_M:
        found.append(f"terrain flat_radius_m = {scenario.terrain.flat_radius_m:g}: the CassiePlant FMU has no "
                     f"parameter for it (always {DEFAULT_FLAT_RADIUS_M:g} m)")
    if abs(scenario.comm_step_s - system.STEP_S) > 1e-12:
        found.append(f"comm_step_s = {scenario.comm_step_s:g}: the system steps every {system.STEP_S:g} s")
    return found


def parameter_values(scenario, arm_name: str) -> dict[str, dict]:
    """{instance: {parameter: value}}: the plant's from the scenario, the regulator's from the arm."""
    from scenarios.cosim.plant_fmu import fmu_parameters

    return {system.PLANT: fmu_parameters(scenario),
            system.REGULATOR: scenario.arm(arm_name).overrides_dict()}


def export_ssp(scenario, arm_name: str, out: str | Path, *, plant_fmu: Path, regulator_fmu: Path,
               command_fmu: Path) -> Path:
    """Write ``out``, the SSP of ``scenario``'s arm ``arm_name``; NotExpressible if it cannot be one."""
    from fmu_src.packing.archive import write_zip
    from fmu_src.command_source.build_command_source import schedule_csv, with_schedule

    found = problems(scenario, arm_name)
    if found:
        raise NotExpressible(found)
    with tempfile.TemporaryDirectory(prefix="cassie_avr_export_") as tmp:
        command = with_schedule(command_fmu, schedule_csv(schedule_rows(scenario)),
                                Path(tmp) / Path(command_fmu).name)
        entries = system.ssp_entries(Path(plant_fmu), Path(regulator_fmu), command,
                                     values=parameter_values(scenario, arm_name), system_name=scenario.name,
                                     description=f"{scenario.name}, arm {arm_name}: {scenario.description}",
                                     stop_s=scenario.duration_s)
    write_zip(entries, Path(out))
    log.info("wrote %s", out)
    return Path(out)


def ensure_command_fmu(fmu: str | Path | None) -> Path:
    """``fmu`` if given, else ``dist/CommandSource_fmi2.fmu``, built if missing or stale."""
    from scenarios.errors import CosimError
    from scenarios.cosim.fmus import REPO_ROOT, _built

    if fmu is not None:
        if not Path(fmu).is_file():
            raise CosimError(f"--command-fmu {fmu}: no such file")
        return Path(fmu)
    folder = REPO_ROOT / "fmu_src" / "command_source"
    sources = [REPO_ROOT / "build.py", *folder.glob("*.py"), *folder.glob("*.[ch]")]
    return _built(REPO_ROOT / "dist" / "CommandSource_fmi2.fmu", sources, ("build_command_source", 2), False)


def cmd_export_ssp(args) -> int:
    """The CLI command (see the module docstring); exit 2 for a scenario or arm it cannot express."""
    import sys

    from scenarios.lang import spec
    from scenarios.errors import ScenarioError
    from scenarios.cosim.fmus import ensure_fmu, ensure_plant_fmu, fmu_file_problem

    given = [p for p in (fmu_file_problem("--fmu", args.fmu, "regulator"),
                         fmu_file_problem("--plant-fmu", args.plant_fmu, "plant"),
                         fmu_file_problem("--command-fmu", args.command_fmu)) if p]
    try:
        (scenario,) = spec.resolve_targets([args.scenario])
        if args.profile is not None:
            scenario = spec.override(scenario, profile=args.profile)
    except ScenarioError as exc:
        print("\n".join([str(exc), *given]), file=sys.stderr)
        return 2
    if given:
        print("\n".join(given), file=sys.stderr)
        return 2
    arm = args.arm or scenario.arms[0].name
    found = problems(scenario, arm)
    if found:
        print(f"{scenario.name}: cannot export arm {arm} as an SSP:", file=sys.stderr)
        for p in found:
            print(f"  {p}", file=sys.stderr)
        return 2
    out = Path(args.out) if args.out else Path(f"{scenario.name}_{arm}.ssp")
    path = export_ssp(scenario, arm, out, plant_fmu=ensure_plant_fmu(args.plant_fmu),
                      regulator_fmu=ensure_fmu(args.fmu), command_fmu=ensure_command_fmu(args.command_fmu))
    print(path)
    return 0


def add_parser(sub) -> None:
    sp = sub.add_parser("export-ssp", help="write a suite scenario's arm as an SSP (plant + regulator + command "
                                           "source FMUs) that any SSP importer runs")
    sp.add_argument("scenario", metavar="SCENARIO", help="a suite scenario's name or a scenario file")
    sp.add_argument("--arm", default=None, help="the arm (one regulator configuration per SSP; default: the first)")
    sp.add_argument("--profile", default=None, metavar="NAME",
                    help="the regulator starts from the named profile (dist/profiles/NAME.ssv) instead of the FMU's "
                         "defaults, as with `run --profile`: the SSP's regulator parameter set holds its values")
    sp.add_argument("--out", default=None, help="the SSP file (default: <scenario>_<arm>.ssp)")
    sp.add_argument("--fmu", type=Path, default=None, help="regulator FMU (default dist/AdaptiveVelocityRegulator.fmu)")
    sp.add_argument("--plant-fmu", type=Path, default=None, help="CassiePlant FMU (default dist/CassiePlant.fmu)")
    sp.add_argument("--command-fmu", type=Path, default=None,
                    help="CommandSource FMU (default dist/CommandSource_fmi2.fmu)")
    sp.set_defaults(func=cmd_export_ssp)
