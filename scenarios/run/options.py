"""The options of one ``python -m scenarios run``: :class:`RunOptions`, decided once from the
command line (:meth:`RunOptions.from_args`, every problem named at once by :meth:`problems`)
and passed whole to the session and the runner, which give the master its part
(regulator, plant, exchange order, recorder)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from scenarios.cosim.fmus import REGULATOR_FMUS, fmu_role_problem, fmu_version_problem

#: ``--regulator``: an FMU kind (:data:`scenarios.cosim.fmus.REGULATOR_FMUS`) or the core in-process.
REGULATORS = (*REGULATOR_FMUS, "inprocess")
#: ``--plant``: MuJoCo in this process or the CassiePlant FMU through fmpy.
PLANTS = ("inprocess", "fmu")
#: What ``run`` does with results of its scenarios already in the results folder.
MODES = ("new", "overwrite", "resume")
#: ``--out`` when not given.
DEFAULT_OUT = Path("runs")


@dataclass(frozen=True)
class RunOptions:
    """Everything a run decides besides its scenarios (which ``targets`` name).

    ``fmu``/``plant_fmu``: the FMU files as given (None: the default file in ``dist/``);
    :meth:`with_fmus` fills in the files the run uses once they are built, and
    ``unpack_dir`` (where each arm extracts its FMUs) once the results folder is taken.
    """

    targets: tuple[str, ...] = ()
    model: str | None = None
    duration_s: float | None = None
    out: Path = DEFAULT_OUT
    regulator: str = "fmu"
    fmu: Path | None = None
    plant: str = "inprocess"
    plant_fmu: Path | None = None
    rebuild_fmu: bool = False
    jobs: int = 1
    plots: bool = True
    render: bool = False
    require_pass: bool = False
    mode: str = "new"
    exchange: str = "gauss-seidel"
    unpack_dir: Path | None = None

    @classmethod
    def from_args(cls, args) -> "RunOptions":
        """The options of the ``run`` command's parsed arguments (:func:`scenarios.run.command.add_arguments`)."""
        mode = "overwrite" if args.overwrite else "resume" if args.resume else "new"
        return cls(targets=tuple(args.targets), model=args.model, duration_s=args.duration, out=Path(args.out),
                   regulator=args.regulator, fmu=args.fmu, plant=args.plant, plant_fmu=args.plant_fmu,
                   rebuild_fmu=args.rebuild_fmu, jobs=args.jobs, plots=not args.no_plots, render=args.render,
                   require_pass=args.require_pass, mode=mode)

    def problems(self) -> list[str]:
        """Every problem of these options, each naming the option and what it allows."""
        from scenarios.cosim.master import EXCHANGES  # here: importing the master loads MuJoCo (--render sets it up first)

        found = []
        for name, value, allowed in (("--regulator", self.regulator, REGULATORS), ("--plant", self.plant, PLANTS),
                                     ("mode", self.mode, MODES), ("exchange", self.exchange, EXCHANGES)):
            if value not in allowed:
                found.append(f"{name} {value}: must be one of {', '.join(allowed)}")
        if isinstance(self.jobs, bool) or not isinstance(self.jobs, int) or self.jobs < 1:
            found.append(f"--jobs {self.jobs}: must be >= 1")
        if self.render and self.plant == "fmu":
            found.append("--render with --plant fmu: the CassiePlant FMU gives no MuJoCo state to render; "
                         "render with --plant inprocess (the same plant)")
        if self.fmu is not None and not Path(self.fmu).is_file():
            found.append(f"--fmu {self.fmu}: no such file")
        elif self.fmu is not None and self.regulator in REGULATOR_FMUS:
            found += filter(None, [fmu_version_problem(self.regulator, Path(self.fmu))
                                   or fmu_role_problem("--fmu", Path(self.fmu), "regulator")])
        if self.plant == "fmu":
            if self.plant_fmu is not None and not Path(self.plant_fmu).is_file():
                found.append(f"--plant-fmu {self.plant_fmu}: no such file")
            elif self.plant_fmu is not None:
                found += filter(None, [fmu_role_problem("--plant-fmu", Path(self.plant_fmu), "plant")])
        return found

    def with_fmus(self, fmu: Path | None, plant_fmu: Path | None) -> "RunOptions":
        """These options with the FMU files the run uses (None: that part runs in-process)."""
        return dataclasses.replace(self, fmu=fmu, plant_fmu=plant_fmu)

    def with_unpack_dir(self, unpack_dir: Path | None) -> "RunOptions":
        """These options with the folder the arms extract their FMUs to."""
        return dataclasses.replace(self, unpack_dir=unpack_dir)
