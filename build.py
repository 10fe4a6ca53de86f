"""Build the regulator FMUs into ``dist/`` reproducibly, and ``dist/fmus.json`` listing them.

``AdaptiveVelocityRegulator.fmu`` (FMI 2.0 co-simulation, pythonfmu, the reference) and
``AdaptiveVelocityRegulatorNative_fmi2.fmu`` / ``_fmi3.fmu`` (the same regulator in C,
FMI 2.0 and FMI 3.0 from one source, linux and windows x86-64 binaries plus sources;
the win64 binaries need the MinGW-w64 cross compiler), the ``CassiePlant.fmu`` and the
CassieAVR system wiring both (SSP archive and OSP folder).

    python build.py [--out DIR] [--sanitize]

Steps for a pythonfmu FMU: pythonfmu packs the slave with its modules; the model
description is post-processed (units, ranges, default experiment, a content-derived
GUID, no generation time), a documentation page and a ``requirements.txt`` are added,
the FMI guard (``fmu_src/guard/*.c``) is compiled as the linux64 library the host loads
(pythonfmu's own library moves beside it as ``<id>_pythonfmu.so``), and the archive is
written with sorted entries and fixed timestamps, so two builds of the same sources give
the same sha256.  Prints each FMU's path and sha256.  ``--sanitize`` compiles the guard
with AddressSanitizer + UndefinedBehaviorSanitizer instead (for the ``sanitize`` tests).
Temporary folders are removed when the build ends, also when it fails.

This file is the entry point and the orchestration; the pieces live beside what they
build: ``fmu_src/avr_packaging/`` (archives and GUIDs, model descriptions, documentation
pages, the pythonfmu library fix, the plant's vendored modules),
``fmu_src/guard/build_guard.py`` and ``fmu_src/native/build_native.py``.
"""
from __future__ import annotations

import argparse
import hashlib
import io
import json
import logging
import sys
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent
if str(REPO_ROOT) not in sys.path:  # build.py also runs without the package installed
    sys.path.insert(0, str(REPO_ROOT))

from fmu_src.guard.build_guard import (GUARD_TEXTS, SANITIZE_FLAGS,  # noqa: E402,F401 (SANITIZE_FLAGS: documented)
                                       compile_guard, guard_header)
from fmu_src.native import build_native  # noqa: E402
from fmu_src.native.build_native import compile_native  # noqa: E402,F401 (the tests' sanitizer build)
from fmu_src.avr_packaging import pages, vendor  # noqa: E402
from fmu_src.avr_packaging.archive import content_guid, read_entries, sha256_of, write_zip  # noqa: E402
from fmu_src.avr_packaging.describe import DEFAULT_EXPERIMENT, UNITS, model_description  # noqa: E402
from fmu_src.avr_packaging.pythonfmu_fix import (EXIT_BUG_PATCH, EXIT_BUG_SYMBOL,  # noqa: E402,F401 (tests)
                                             _elf_symbol_file_offset, patch_pythonfmu_exit_bug)

FMU_SRC = REPO_ROOT / "fmu_src"
SLAVE_SCRIPT = FMU_SRC / "avr_slave.py"
#: The regulator FMU's modules besides the slave script (flat in resources/); the plant FMU
#: vendors them too: its slave uses avr_slavebase, its core avr_specs.
PROJECT_FILES = tuple(FMU_SRC / f"avr_{name}.py" for name in (
    "core", "errors", "fmustate", "network", "params", "regulator", "slavebase", "specs", "statebytes"))
MODEL_IDENTIFIER = "AdaptiveVelocityRegulator"
DEFAULT_OUT = REPO_ROOT / "dist"
REQUIREMENTS = "numpy>=1.24\n"
FMUS_JSON = "fmus.json"
PLANT_SLAVE_SCRIPT = FMU_SRC / "cassie_plant_slave.py"
PLANT_IDENTIFIER = "CassiePlant"
#: The plant package and its project imports travel in resources/<PLANT_LIB>/ (see the slave).
PLANT_LIB = "cassie_plant_lib"
DEG_TO_RAD = 3.141592653589793 / 180
PLANT_UNITS = {"1": {}, "m": {"m": "1"}, "N": {"kg": "1", "m": "1", "s": "-2"}, "kg": {"kg": "1"},
               "deg": {"rad": "1", "factor": repr(DEG_TO_RAD)}}
PLANT_REQUIREMENTS = "numpy>=1.24\nmujoco>=3.2\n"
PYTHONFMU_LINUX = "binaries/linux64/{}.so"

log = logging.getLogger("avr_build")


def _specs():
    from fmu_src.avr_core import INPUT_SPECS, OUTPUT_SPECS, PARAM_SPECS

    return (*PARAM_SPECS, *INPUT_SPECS, *OUTPUT_SPECS)


def _pythonfmu_entries(slave_script: Path, project_files, dest: Path) -> dict[str, bytes]:
    """Every file of the FMU pythonfmu builds for ``slave_script`` (with FMU state support)."""
    from pythonfmu.builder import FmuBuilder

    raw = FmuBuilder.build_FMU(slave_script, dest=dest, project_files=list(project_files),
                               canGetAndSetFMUstate=True, canSerializeFMUstate=True)
    return read_entries(raw)


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
    write_zip(entries, fmu_path)
    log.info("built %s", fmu_path)
    return fmu_path


def build_fmu(out_dir: Path = DEFAULT_OUT, sanitize: bool = False) -> Path:
    """Build ``<out_dir>/AdaptiveVelocityRegulator.fmu`` and return its path.

    ``sanitize``: compile the FMI guard with AddressSanitizer and UndefinedBehaviorSanitizer
    (``SANITIZE_FLAGS``), for tests only: a host must then preload libasan (see the README).
    """
    specs = _specs()
    with tempfile.TemporaryDirectory(prefix="avr_fmu_") as tmp:
        entries = _pythonfmu_entries(SLAVE_SCRIPT, PROJECT_FILES, Path(tmp))
    tree = model_description(entries.pop("modelDescription.xml"), specs)
    entries["documentation/index.html"] = pages.regulator_page(MODEL_IDENTIFIER, specs).encode("utf-8")
    entries["resources/requirements.txt"] = REQUIREMENTS.encode("utf-8")
    _move_pythonfmu_library(entries, MODEL_IDENTIFIER)
    slave_module = entries["resources/slavemodule.txt"].decode("utf-8").strip()
    return _guarded_fmu(entries, tree, MODEL_IDENTIFIER, out_dir, header_options={"slave_module": slave_module},
                        sanitize=sanitize)


def build_native_fmu(fmi_version: int, out_dir: Path = DEFAULT_OUT) -> Path:
    """Build ``<out_dir>/AdaptiveVelocityRegulatorNative_fmi<2|3>.fmu`` (linux and windows x86-64) reproducibly."""
    fmu_path = Path(out_dir) / build_native.fmu_name(fmi_version)
    write_zip(build_native.fmu_entries(fmi_version, UNITS, DEFAULT_EXPERIMENT), fmu_path)
    log.info("built %s", fmu_path)
    return fmu_path


def _plant_entries(tmp: Path) -> dict[str, bytes]:
    """pythonfmu's CassiePlant FMU with the plant modules and models in resources/, linux64 only."""
    lib = tmp / "stage" / PLANT_LIB
    vendor.vendor_plant(lib, PROJECT_FILES)
    vendor.copy_models(lib / "models")
    entries = _pythonfmu_entries(PLANT_SLAVE_SCRIPT, [lib], tmp / "raw")
    if PYTHONFMU_LINUX.format(PLANT_IDENTIFIER) not in entries:
        import pythonfmu

        raise RuntimeError(f"pythonfmu came from {Path(pythonfmu.__file__).parent}, which has no binaries (an FMU's "
                           "resources copy, imported after a pythonfmu FMU was loaded): build in a fresh process")
    for name in [n for n in entries if n.startswith("binaries/") and not n.startswith("binaries/linux64/")]:
        del entries[name]  # the guard is built for linux64 only: without it a refusal could only be fmi2Fatal
    return entries


def build_plant_fmu(out_dir: Path = DEFAULT_OUT, sanitize: bool = False) -> Path:
    """Build ``<out_dir>/CassiePlant.fmu`` (FMI 2.0 co-simulation, linux64) and return its path.

    ``sanitize``: the guard with AddressSanitizer and UBSan, as for ``build_fmu`` (tests only).
    """
    from plant import fmu_core

    with tempfile.TemporaryDirectory(prefix="cassie_plant_fmu_") as tmp:
        entries = _plant_entries(Path(tmp))
    tree = model_description(entries.pop("modelDescription.xml"), fmu_core.SPECS, PLANT_UNITS)
    entries["documentation/index.html"] = pages.plant_page(PLANT_IDENTIFIER, PLANT_LIB, fmu_core.SPECS).encode("utf-8")
    entries["resources/requirements.txt"] = PLANT_REQUIREMENTS.encode("utf-8")
    _move_pythonfmu_library(entries, PLANT_IDENTIFIER)
    options = {"slave_module": PLANT_SLAVE_SCRIPT.stem, "step_quantum_s": fmu_core.PLANT_STEP_S,
               "max_step_s": fmu_core.MAX_STEP_S}
    return _guarded_fmu(entries, tree, PLANT_IDENTIFIER, out_dir, guid_prefix=f"{PLANT_IDENTIFIER}:",
                        header_options=options, sanitize=sanitize)


def build_ssp(out_dir: Path, plant_fmu: Path, regulator_fmu: Path) -> Path:
    """Write ``<out_dir>/CassieAVR.ssp``: both FMUs wired name to name, the nominal parameter sets and a
    30 s, 5 ms default experiment (the structure is ``scenarios/system.py``'s); reproducible zip."""
    from scenarios import system

    path = Path(out_dir) / f"{system.SYSTEM_NAME}.ssp"
    write_zip(system.ssp_entries(Path(plant_fmu), Path(regulator_fmu)), path)
    return path


def build_osp(out_dir: Path, plant_fmu: Path, regulator_fmu: Path) -> Path:
    """Write the folder ``<out_dir>/CassieAVR_osp/``: OspSystemStructure.xml beside copies of both FMUs."""
    import shutil

    from scenarios import system

    folder = Path(out_dir) / f"{system.SYSTEM_NAME}_osp"
    folder.mkdir(parents=True, exist_ok=True)
    for fmu in (plant_fmu, regulator_fmu):
        shutil.copyfile(fmu, folder / Path(fmu).name)
    (folder / "OspSystemStructure.xml").write_bytes(system.osp_system_structure(Path(plant_fmu), Path(regulator_fmu)))
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


def build_all(out_dir: Path = DEFAULT_OUT, *, sanitize: bool = False) -> list[Path]:
    """Build every FMU (the pythonfmu regulator, both native regulators, the CassiePlant
    FMU), ``<out_dir>/fmus.json`` listing them, and the CassieAVR system (SSP and OSP)."""
    regulator = build_fmu(out_dir, sanitize=sanitize)
    built = [(regulator, "python")] + [(build_native_fmu(v, out_dir), "native") for v in (2, 3)]
    plant = build_plant_fmu(out_dir)
    built.append((plant, "python"))
    listing = {"fmus": [fmu_entry(path, kind) for path, kind in built]}
    tmp = Path(out_dir) / (FMUS_JSON + ".tmp")
    tmp.write_text(json.dumps(listing, indent=2) + "\n")
    tmp.replace(Path(out_dir) / FMUS_JSON)
    return [path for path, _ in built] + [build_ssp(out_dir, plant, regulator), build_osp(out_dir, plant, regulator)]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder (default: dist/)")
    parser.add_argument("--sanitize", action="store_true",
                        help="compile the FMI guard with AddressSanitizer + UndefinedBehaviorSanitizer (for testing; "
                             "hosts must preload libasan)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    for path in build_all(args.out, sanitize=args.sanitize):
        print(path if path.suffix != ".fmu" else f"{path}\nsha256 {sha256_of(path)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
