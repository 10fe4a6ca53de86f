"""Build the regulator FMUs into ``dist/`` reproducibly, and ``dist/fmus.json`` listing them.

``AdaptiveVelocityRegulator.fmu`` (FMI 2.0 co-simulation, pythonfmu, the reference) and
``AdaptiveVelocityRegulatorNative_fmi2.fmu`` / ``_fmi3.fmu`` (the same regulator in C,
FMI 2.0 and FMI 3.0 from one source, Linux and Windows x86-64 binaries, FMI 3.0 also Linux
aarch64, plus sources), the ``CassiePlant.fmu``, the ``CommandSource_fmi2.fmu`` (native C:
the command and pushes over time, from its ``resources/schedule.csv``), the CassieAVR
system wiring the three (SSP archive and OSP folder), the ``CassiePlantNative_fmi2.fmu`` /
``_fmi3.fmu`` (the plant in C over MuJoCo's C API, no Python) and ``CassieAVRNative.ssp`` (the
system of native FMUs only).  The native FMUs' Windows and aarch64
binaries need cross compilers (Debian ``gcc-mingw-w64-x86-64``, ``gcc-aarch64-linux-gnu``);
without one, its platform is skipped with a warning naming the package, and the build goes on.

    python build.py [--out DIR] [--sanitize]
    python build.py --parameter-table    # only docs/fmus.md's parameter table, from fmu_src/core

Steps for a pythonfmu FMU: the slave and its modules become one package imported under a name
private to the build (``fmu_src/packing/pack.py``), which pythonfmu packs; the model
description is post-processed (units, ranges, default experiment, a content-derived
GUID, no generation time), a documentation page and a ``requirements.txt`` are added,
the FMI guard (``fmu_src/regulator_fmu/guard/*.c``) is compiled as the linux64 library the host loads
(pythonfmu's own library moves beside it as ``<id>_pythonfmu.so``), and the archive is
written with sorted entries and fixed timestamps, so two builds of the same sources give
the same sha256.  Every FMU build function then simulates the FMU it wrote once with FMPy
and puts the results inside (``extra/org.fmi-standard.fmi-ls-ref/``, the fmi-ls-ref layered
standard; ``fmu_src/packing/crosscheck.py``), so an FMU is the same file whoever builds
it.  Prints each FMU's path and sha256.  ``--sanitize`` compiles the guard
with AddressSanitizer + UndefinedBehaviorSanitizer instead (for the ``sanitize`` tests).
Temporary folders are removed when the build ends, also when it fails.

This file is the entry point and the orchestration; the pieces live beside what they
build: ``fmu_src/packing/`` (archives and GUIDs, model descriptions, documentation
pages, the pythonfmu library fix, the plant's vendored modules),
``fmu_src/regulator_fmu/guard/build_guard.py`` and ``fmu_src/regulator_fmu/native/build_native.py``.
"""
from __future__ import annotations

import hashlib
import io
import json
import logging
import os
import sys
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent
if str(REPO_ROOT) not in sys.path:  # build.py also runs without the package installed
    sys.path.insert(0, str(REPO_ROOT))

from fmu_src.regulator_fmu.guard.build_guard import (GUARD_TEXTS, SANITIZE_FLAGS,  # noqa: E402,F401 (SANITIZE_FLAGS: documented)
                                       compile_guard, guard_header)
from fmu_src.regulator_fmu.native import build_native  # noqa: E402
from fmu_src.command_source import build_command_source as command_source  # noqa: E402
from fmu_src.regulator_fmu.native.build_native import compile_native  # noqa: E402,F401 (the tests' sanitizer build)
from fmu_src.packing import crosscheck, pack, pages, vendor  # noqa: E402
from fmu_src.packing.archive import content_guid, read_entries, sha256_of, write_zip  # noqa: E402
from fmu_src.packing.describe import (DEFAULT_EXPERIMENT, PLANT_INITIAL_UNKNOWNS, UNITS,  # noqa: E402
                                            model_description)
from fmu_src.packing.pythonfmu_fix import (EXIT_BUG_PATCH, EXIT_BUG_SYMBOL,  # noqa: E402,F401 (tests)
                                             _elf_symbol_file_offset, patch_pythonfmu_exit_bug)

FMU_SRC = REPO_ROOT / "fmu_src"
SLAVE_SCRIPT = FMU_SRC / "regulator_fmu" / "avr_slave.py"
MODEL_IDENTIFIER = "AdaptiveVelocityRegulator"
#: The regulator's package folder in resources/.
REGULATOR_LIB = "avr_regulator_lib"
DEFAULT_OUT = REPO_ROOT / "dist"
REQUIREMENTS = "numpy>=1.24\n"
FMUS_JSON = "fmus.json"
PLANT_SLAVE_SCRIPT = FMU_SRC / "plant_fmu" / "cassie_plant_slave.py"
PLANT_IDENTIFIER = "CassiePlant"
#: The plant's package folder in resources/ (with the models and their licenses, see the slave).
PLANT_LIB = "cassie_plant_lib"
DEG_TO_RAD = 3.141592653589793 / 180
PLANT_UNITS = {"1": {}, "m": {"m": "1"}, "N": {"kg": "1", "m": "1", "s": "-2"}, "kg": {"kg": "1"},
               "deg": {"rad": "1", "factor": repr(DEG_TO_RAD)}}
PLANT_REQUIREMENTS = "numpy>=1.24\nmujoco>=3.2\n"
PYTHONFMU_LINUX = "binaries/linux64/{}.so"

log = logging.getLogger("avr_build")


def _specs():
    from fmu_src.core.avr_specs import INPUT_SPECS, OUTPUT_SPECS, PARAM_SPECS

    return (*PARAM_SPECS, *INPUT_SPECS, *OUTPUT_SPECS)


def _pythonfmu_entries(packed: pack.Packed, dest: Path, identifier: str) -> dict[str, bytes]:
    """Every file of the FMU ``identifier`` that pythonfmu builds for the staged code ``packed`` (with FMU
    state support); RuntimeError when the pythonfmu imported here has no binaries to put in it."""
    from pythonfmu.builder import FmuBuilder

    path_before = list(sys.path)
    try:
        raw = FmuBuilder.build_FMU(packed.entry, dest=dest, project_files=[packed.lib],
                                   canGetAndSetFMUstate=True, canSerializeFMUstate=True)
    finally:  # the builder imports the entry from the staging folder, which is about to be deleted
        sys.path[:] = [p for p in sys.path if p in path_before]
        for name in [n for n in sys.modules if n == packed.module or n == packed.package
                     or n.startswith(packed.package + ".")]:
            del sys.modules[name]
    entries = read_entries(raw)
    if PYTHONFMU_LINUX.format(identifier) not in entries:
        import pythonfmu

        raise RuntimeError(f"pythonfmu came from {Path(pythonfmu.__file__).parent}, which has no binaries (an FMU's "
                           "resources copy, imported after a pythonfmu FMU was loaded): build in a fresh process")
    return entries


def _move_pythonfmu_library(entries: dict[str, bytes], identifier: str) -> None:
    """pythonfmu's linux64 library, fixed, goes beside the guard as ``<identifier>_pythonfmu.so``."""
    inner = entries.pop(PYTHONFMU_LINUX.format(identifier))
    entries[PYTHONFMU_LINUX.format(f"{identifier}_pythonfmu")] = patch_pythonfmu_exit_bug(inner)


def _guarded_fmu(entries: dict[str, bytes], tree: ET.ElementTree, identifier: str, out_dir: Path, *,
                 guid_prefix: str = "", header_options: dict, sanitize: bool) -> Path:
    """Set the content GUID, compile the guard as ``binaries/linux64/<identifier>.so`` and write
    ``<out_dir>/<identifier>.fmu``.  The GUID hashes everything but the guard library (which
    embeds it): the model description, the guard's sources and every other entry."""
    digest = hashlib.sha256(ET.tostring(tree.getroot()))
    for source in GUARD_TEXTS:
        digest.update(source.read_bytes())
    guid = content_guid(digest, entries, prefix=guid_prefix)
    tree.getroot().set("guid", guid)
    with tempfile.TemporaryDirectory(prefix="avr_guard_out_") as tmp:
        guard_path = Path(tmp) / f"{identifier}.so"
        header = guard_header(tree.getroot(), guid, f"{identifier}_pythonfmu.so", **header_options)
        compile_guard(header, guard_path, sanitize)
        entries[PYTHONFMU_LINUX.format(identifier)] = guard_path.read_bytes()
    xml_out = io.BytesIO()
    tree.write(xml_out, encoding="UTF-8", xml_declaration=True)
    entries["modelDescription.xml"] = xml_out.getvalue()
    fmu_path = Path(out_dir) / f"{identifier}.fmu"
    write_zip(entries, fmu_path, compress=sanitize)  # else a draft: add_reference writes it again
    log.info("built %s", fmu_path)
    return fmu_path


def build_fmu(out_dir: Path = DEFAULT_OUT, sanitize: bool = False) -> Path:
    """Build ``<out_dir>/AdaptiveVelocityRegulator.fmu`` and return its path.

    ``sanitize``: compile the FMI guard with AddressSanitizer and UndefinedBehaviorSanitizer
    (``SANITIZE_FLAGS``), for tests only: a host must then preload libasan (see the README).
    """
    specs = _specs()
    with tempfile.TemporaryDirectory(prefix="avr_fmu_") as tmp:
        packed = pack.pack(Path(tmp) / "stage", SLAVE_SCRIPT, MODEL_IDENTIFIER, REGULATOR_LIB)
        entries = _pythonfmu_entries(packed, Path(tmp) / "raw", MODEL_IDENTIFIER)
    tree = model_description(entries.pop("modelDescription.xml"), specs)
    entries["documentation/index.html"] = pages.regulator_page(MODEL_IDENTIFIER, specs).encode("utf-8")
    entries["resources/requirements.txt"] = REQUIREMENTS.encode("utf-8")
    _move_pythonfmu_library(entries, MODEL_IDENTIFIER)
    fmu_path = _guarded_fmu(entries, tree, MODEL_IDENTIFIER, out_dir, header_options={"slave_module": packed.module},
                            sanitize=sanitize)
    return crosscheck.add_reference(fmu_path, sanitize=sanitize)


def build_native_fmu(fmi_version: int, out_dir: Path = DEFAULT_OUT) -> Path:
    """Build ``<out_dir>/AdaptiveVelocityRegulatorNative_fmi<2|3>.fmu`` reproducibly, with the binaries of
    every platform whose compiler is installed (``build_native.PLATFORMS``)."""
    fmu_path = Path(out_dir) / build_native.fmu_name(fmi_version)
    write_zip(build_native.fmu_entries(fmi_version, UNITS, DEFAULT_EXPERIMENT), fmu_path, compress=False)  # a draft
    log.info("built %s", fmu_path)
    return crosscheck.add_reference(fmu_path)


def build_native_plant_fmu(fmi_version: int = 2, out_dir: Path = DEFAULT_OUT) -> Path:
    """Build ``<out_dir>/CassiePlantNative_fmi<2|3>.fmu``: the CassiePlant FMU in C, no Python
    (``fmu_src/plant_fmu/native/build_native_plant.py``), for Linux and Windows x86-64."""
    from fmu_src.plant_fmu.native import build_native_plant

    fmu_path = Path(out_dir) / build_native_plant.fmu_name(fmi_version)
    write_zip(build_native_plant.fmu_entries(fmi_version, PLANT_UNITS), fmu_path, compress=False)  # a draft
    log.info("built %s", fmu_path)
    return crosscheck.add_reference(fmu_path)


def _plant_entries(tmp: Path) -> tuple[pack.Packed, dict[str, bytes]]:
    """pythonfmu's CassiePlant FMU with the plant's package, data and models in resources/, linux64 only."""
    def data(lib: Path) -> None:
        vendor.copy_plant_data(lib)
        vendor.copy_models(lib / "models")

    packed = pack.pack(tmp / "stage", PLANT_SLAVE_SCRIPT, PLANT_IDENTIFIER, PLANT_LIB, fill=data)
    entries = _pythonfmu_entries(packed, tmp / "raw", PLANT_IDENTIFIER)
    for name in [n for n in entries if n.startswith("binaries/") and not n.startswith("binaries/linux64/")]:
        del entries[name]  # the guard is built for linux64 only: without it a refusal could only be fmi2Fatal
    return packed, entries


def build_plant_fmu(out_dir: Path = DEFAULT_OUT, sanitize: bool = False) -> Path:
    """Build ``<out_dir>/CassiePlant.fmu`` (FMI 2.0 co-simulation, linux64) and return its path.

    ``sanitize``: the guard with AddressSanitizer and UBSan, as for ``build_fmu`` (tests only).
    """
    from fmu_src.plant_fmu import fmu_core

    with tempfile.TemporaryDirectory(prefix="cassie_plant_fmu_") as tmp:
        packed, entries = _plant_entries(Path(tmp))
    tree = model_description(entries.pop("modelDescription.xml"), fmu_core.SPECS, PLANT_UNITS,
                             initial_unknowns=PLANT_INITIAL_UNKNOWNS)
    entries["documentation/index.html"] = pages.plant_page(PLANT_IDENTIFIER, PLANT_LIB, fmu_core.SPECS).encode("utf-8")
    entries["resources/requirements.txt"] = PLANT_REQUIREMENTS.encode("utf-8")
    _move_pythonfmu_library(entries, PLANT_IDENTIFIER)
    options = {"slave_module": packed.module, "step_quantum_s": fmu_core.PLANT_STEP_S,
               "max_step_s": fmu_core.MAX_STEP_S}
    fmu_path = _guarded_fmu(entries, tree, PLANT_IDENTIFIER, out_dir, guid_prefix=f"{PLANT_IDENTIFIER}:",
                            header_options=options, sanitize=sanitize)
    return crosscheck.add_reference(fmu_path, sanitize=sanitize)


def build_command_source(fmi_version: int, out_dir: Path = DEFAULT_OUT) -> Path:
    """Build ``<out_dir>/CommandSource_fmi<2|3>.fmu`` (the native regulator's platforms, the nominal
    schedule: 0.5 m/s, no turn, no push) reproducibly."""
    path = Path(out_dir) / command_source.fmu_name(fmi_version)
    write_zip(command_source.fmu_entries(fmi_version), path, compress=False)  # a draft
    log.info("built %s", path)
    return crosscheck.add_reference(path)


def build_ssp(out_dir: Path, plant_fmu: Path, regulator_fmu: Path, command_fmu: Path | None = None) -> Path:
    """Write ``<out_dir>/CassieAVR.ssp``: the plant, the regulator and the command source (its
    nominal schedule, built into ``out_dir`` if not given) wired name to name, every
    parameter at its start value in the parameter sets, a 30 s, 5 ms default experiment
    (the structure is ``scenarios/ssp/system.py``'s); reproducible zip."""
    from scenarios.ssp import system

    command_fmu = command_fmu or build_command_source(2, out_dir)
    path = Path(out_dir) / f"{system.SYSTEM_NAME}.ssp"
    write_zip(system.ssp_entries(Path(plant_fmu), Path(regulator_fmu), Path(command_fmu)), path)
    return path


def build_native_ssp(out_dir: Path, plant_fmu: Path, regulator_fmu: Path, command_fmu: Path) -> Path:
    """Write ``<out_dir>/CassieAVRNative.ssp``: the system of ``build_ssp`` made of native FMUs only
    (the native plant, the native regulator, the command source: FMI 2.0, no Python anywhere)."""
    from scenarios.ssp import system

    path = Path(out_dir) / f"{system.SYSTEM_NAME}Native.ssp"
    write_zip(system.ssp_entries(Path(plant_fmu), Path(regulator_fmu), Path(command_fmu),
                                 system_name=f"{system.SYSTEM_NAME}Native",
                                 description="MuJoCo Cassie closed around the adaptive velocity regulator, native "
                                             "FMUs only (no Python), the command and pushes from the command source"),
              path)
    return path


def build_osp(out_dir: Path, plant_fmu: Path, regulator_fmu: Path, command_fmu: Path | None = None) -> Path:
    """Write the folder ``<out_dir>/CassieAVR_osp/``: OspSystemStructure.xml beside copies of the three FMUs."""
    import shutil

    from scenarios.ssp import system

    command_fmu = command_fmu or build_command_source(2, out_dir)
    folder = Path(out_dir) / f"{system.SYSTEM_NAME}_osp"
    folder.mkdir(parents=True, exist_ok=True)
    for fmu in (plant_fmu, regulator_fmu, command_fmu):
        shutil.copyfile(fmu, folder / Path(fmu).name)
    (folder / "OspSystemStructure.xml").write_bytes(
        system.osp_system_structure(Path(plant_fmu), Path(regulator_fmu), Path(command_fmu)))
    return folder


def fmu_entry(path: Path, implementation: str) -> dict:
    """One ``fmus.json`` entry, read back from the built FMU itself."""
    with zipfile.ZipFile(path) as archive:
        root = ET.fromstring(archive.read("modelDescription.xml"))
        platforms = sorted({name.split("/")[1] for name in archive.namelist()
                            if name.startswith("binaries/") and name.count("/") >= 2 and not name.endswith("/")})
    return {"file": Path(path).name, "fmiVersion": root.get("fmiVersion"),
            "modelIdentifier": root.find("CoSimulation").get("modelIdentifier"),
            "implementation": implementation, "platforms": platforms, "sha256": sha256_of(path)}


def build_all(out_dir: Path = DEFAULT_OUT, *, sanitize: bool = False, jobs: int | None = None) -> list[Path]:
    """Build every FMU (the pythonfmu regulator, both native regulators, the CassiePlant
    FMU, the CommandSource FMUs, FMI 2.0 and 3.0, the native CassiePlantNative FMUs, FMI 2.0 and 3.0),
    each with its reference results inside, the FMI cross-check vendor tree
    ``<out_dir>/cross-check/`` (``fmu_src/packing/crosscheck.py``), ``<out_dir>/fmus.json``
    listing the FMUs, the CassieAVR system (SSP and OSP) and the Python-free CassieAVRNative SSP.

    The FMUs are built ``jobs`` at a time (default: one per CPU), in threads: their compilers and
    reference simulations are processes of their own.  The two pythonfmu builds run one after
    the other (pythonfmu's builder imports the slave through ``sys.path``); every FMU is the
    same file whatever ``jobs`` is."""
    from fmu_src.plant_fmu.native import build_native_plant  # noqa: F401 (imported here, not in a thread)

    def pythonfmu_builds() -> tuple[Path, Path]:
        return build_fmu(out_dir, sanitize=sanitize), build_plant_fmu(out_dir)

    # longest first: the pool's last task is then a short one
    tasks = {"native_plants": lambda v: build_native_plant_fmu(v, out_dir), "native": lambda v: build_native_fmu(v, out_dir),
             "command": lambda v: build_command_source(v, out_dir)}
    with ThreadPoolExecutor(max_workers=max(1, jobs or os.cpu_count() or 1), thread_name_prefix="build") as pool:
        futures = {(name, v): pool.submit(make, v) for name, make in tasks.items() for v in (3, 2)}
        python = pool.submit(pythonfmu_builds)
        try:
            done = {key: f.result() for key, f in futures.items()}
            regulator, plant = python.result()
        except BaseException:
            pool.shutdown(cancel_futures=True)
            raise
    native_regulators = [done["native", v] for v in (2, 3)]
    built = [(regulator, "python")] + [(path, "native") for path in native_regulators]
    built.append((plant, "python"))
    command, command3 = (done["command", v] for v in (2, 3))
    built += [(command, "native"), (command3, "native")]
    native_plants = [done["native_plants", v] for v in (2, 3)]
    built += [(path, "native") for path in native_plants]
    crosscheck.write_vendor_tree(out_dir, [path for path, _ in built], build_native.describe.VERSION)
    listing = {"fmus": [fmu_entry(path, kind) for path, kind in built]}
    tmp = Path(out_dir) / (FMUS_JSON + ".tmp")
    tmp.write_text(json.dumps(listing, indent=2) + "\n")
    tmp.replace(Path(out_dir) / FMUS_JSON)
    from scenarios.ssp.profiles import write_profiles

    return [path for path, _ in built] + write_profiles(out_dir) + [build_ssp(out_dir, plant, regulator, command),
                                          build_osp(out_dir, plant, regulator, command),
                                          build_native_ssp(out_dir, native_plants[0], native_regulators[0], command)]


def main(argv=None) -> int:
    from scenarios.lang.cmdline import Parser

    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder (default: dist/)")
    parser.add_argument("--sanitize", action="store_true",
                        help="compile the FMI guard with AddressSanitizer + UndefinedBehaviorSanitizer (for testing; "
                             "hosts must preload libasan)")
    parser.add_argument("--parameter-table", action="store_true",
                        help="only rewrite the regulator's parameter table in docs/fmus.md from fmu_src/core "
                             "(fmu_src/packing/parameters.py) and build nothing")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    if args.parameter_table:
        from fmu_src.packing.parameters import write_parameter_table

        page = Path(__file__).resolve().parent / "docs" / "fmus.md"
        print(f"{page}: {'rewritten' if write_parameter_table(page) else 'unchanged'}")
        return 0
    for path in build_all(args.out, sanitize=args.sanitize):
        print(path if path.suffix != ".fmu" else f"{path}\nsha256 {sha256_of(path)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
