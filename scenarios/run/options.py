"""The options of one ``python -m scenarios run``: :class:`RunOptions`, decided once from the
command line (:meth:`RunOptions.from_args`, every problem named at once by :meth:`problems`)
and passed whole to the session and the runner, which give the master its part
(regulator, plant, exchange order, recorder)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from fmu_src.packing.archive import sha256_of
from plant.constants import CONTROLLERS
from scenarios.cosim.fmus import (REGULATOR_FMUS, fmu_file_problem, fmu_role_problem, fmu_version_problem,
                                  regulator_kind)

#: ``--regulator``: an FMU kind (:data:`scenarios.cosim.fmus.REGULATOR_FMUS`) or the core in-process.
REGULATORS = (*REGULATOR_FMUS, "inprocess")
#: The defaults: the fastest path whose results are byte-identical to the reference path
#: (``--regulator fmu --controller python``): the native regulator FMU (the C twin of the numpy
#: core) and the C walking controller (the Python controller's operations in C).
DEFAULT_REGULATOR = "native"
DEFAULT_CONTROLLER = "native"
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
    ``controller``: the walking controller of the in-process plant (``--plant fmu``: the
    CassiePlant FMU's own, Python); ``controller_lib``: the built C controller it loads
    (:meth:`with_controller_lib`).
    """

    targets: tuple[str, ...] = ()
    model: str | None = None
    duration_s: float | None = None
    profile: str | None = None
    out: Path = DEFAULT_OUT
    regulator: str = DEFAULT_REGULATOR
    fmu: Path | None = None
    controller: str = DEFAULT_CONTROLLER
    controller_lib: Path | None = None
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
        controller = args.controller
        if controller is None:  # the CassiePlant FMU carries its own (Python) controller
            controller = "python" if args.plant == "fmu" else DEFAULT_CONTROLLER
        return cls(targets=tuple(args.targets), model=args.model, duration_s=args.duration, profile=args.profile,
                   out=Path(args.out),
                   regulator=resolve_regulator(args.regulator, args.fmu), fmu=args.fmu, controller=controller, plant=args.plant,
                   plant_fmu=args.plant_fmu,
                   rebuild_fmu=args.rebuild_fmu, jobs=args.jobs, plots=not args.no_plots, render=args.render,
                   require_pass=args.require_pass, mode=mode)

    def problems(self) -> list[str]:
        """Every problem of these options, each naming the option and what it allows."""
        from scenarios.cosim.master import EXCHANGES  # here: importing the master loads MuJoCo (--render sets it up first)

        found = []
        for name, value, allowed in (("--regulator", self.regulator, REGULATORS), ("--plant", self.plant, PLANTS),
                                     ("--controller", self.controller, CONTROLLERS),
                                     ("mode", self.mode, MODES), ("exchange", self.exchange, EXCHANGES)):
            if value not in allowed:
                found.append(f"{name} {value}: must be one of {', '.join(allowed)}")
        if isinstance(self.jobs, bool) or not isinstance(self.jobs, int) or self.jobs < 1:
            found.append(f"--jobs {self.jobs}: must be >= 1")
        if self.render and self.plant == "fmu":
            found.append("--render with --plant fmu: the CassiePlant FMU gives no MuJoCo state to render; "
                         "render with --plant inprocess (the same plant)")
        if self.controller == "native" and self.plant == "fmu":
            found.append("--controller native with --plant fmu: the CassiePlant FMU runs its own (Python) "
                         "controller; use --plant inprocess, or --controller python")
        elif self.controller == "native":
            found += filter(None, [controller_problem()])
        if self.fmu is not None and not Path(self.fmu).is_file():
            found.append(fmu_file_problem("--fmu", self.fmu))
        elif self.fmu is not None and self.regulator in REGULATOR_FMUS:
            found += filter(None, [fmu_version_problem(self.regulator, Path(self.fmu))
                                   or fmu_role_problem("--fmu", Path(self.fmu), "regulator")])
        if self.plant == "fmu":
            found += filter(None, [fmu_file_problem("--plant-fmu", self.plant_fmu, "plant")])
        return found

    def with_fmus(self, fmu: Path | None, plant_fmu: Path | None) -> "RunOptions":
        """These options with the FMU files the run uses (None: that part runs in-process)."""
        return dataclasses.replace(self, fmu=fmu, plant_fmu=plant_fmu)

    def with_controller_lib(self, controller_lib: Path | None) -> "RunOptions":
        """These options with the C controller library the arms load (None: the Python controller)."""
        return dataclasses.replace(self, controller_lib=controller_lib)

    def path_record(self) -> dict:
        """The implementations this run's results come from, for ``summary.json``'s ``path``: the
        regulator (and its FMU file with its SHA-256), the plant (and its FMU), the walking controller."""
        record = {"regulator": self.regulator, "regulator_fmu": None, "regulator_fmu_sha256": None,
                  "plant": self.plant, "plant_fmu": None, "plant_fmu_sha256": None,
                  "controller": self.controller}
        for key, path in (("regulator_fmu", self.fmu), ("plant_fmu", self.plant_fmu)):
            if path is not None and Path(path).is_file():
                record[key], record[f"{key}_sha256"] = str(Path(path).resolve()), sha256_of(Path(path))
        return record

    def with_unpack_dir(self, unpack_dir: Path | None) -> "RunOptions":
        """These options with the folder the arms extract their FMUs to."""
        return dataclasses.replace(self, unpack_dir=unpack_dir)


def resolve_regulator(regulator: str | None, fmu: Path | None) -> str:
    """``--regulator`` as given; when not given, the kind of the ``--fmu`` file if there is one
    (:func:`scenarios.cosim.fmus.regulator_kind`), else :data:`DEFAULT_REGULATOR`."""
    if regulator is not None:
        return regulator
    if fmu is not None and Path(fmu).is_file():
        return regulator_kind(Path(fmu), DEFAULT_REGULATOR)
    return DEFAULT_REGULATOR


def controller_problem() -> str | None:
    """Why ``--controller native`` cannot be built here (no C compiler and no library built
    before for these sources), or None."""
    from plant.native.native_ctrl import CACHE_PREFIX, find_compiler, library_key
    from plant.sim import NATIVE_CACHE

    if find_compiler() is not None or (NATIVE_CACHE / f"{CACHE_PREFIX}{library_key()}" / "libcassie_ctrl.so").is_file():
        return None
    return ("--controller native: no C compiler (cc or gcc; set CC) to build the C walking controller; "
            "install one, or choose --controller python (the same controller in Python, the same results)")
