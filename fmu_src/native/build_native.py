"""Build the native FMUs (FMI 2.0 and FMI 3.0 from the one C source in this folder): their
``sources/`` (C files, headers, the generated ``avr_vars.h``/``avr_guid.h``, the FMI headers),
model description, documentation and the binaries: Linux and Windows x86-64, and for FMI 3.0
also Linux aarch64 (FMI 2.0 has no platform name for it).  A platform whose cross compiler
is not installed is skipped with a warning naming its Debian package (``compiler.py``); the
FMU's documentation lists the platforms it carries."""
from __future__ import annotations

import hashlib
import logging
import shutil
import tempfile
from pathlib import Path

from fmu_src.packing import compiler
from fmu_src.packing.archive import PLACEHOLDER_GUID, content_guid
from fmu_src.native import describe, header

NATIVE_SRC = Path(__file__).resolve().parent
MODEL_IDENTIFIER = "AdaptiveVelocityRegulatorNative"
CORE_SOURCES = ("avr_model.c", "avr_instance.c", "avr_state.c")
API_SOURCES = {2: ("fmi2_api.c",), 3: ("fmi3_api.c", "fmi3_refused.c")}
HEADERS = ("avr_types.h", "avr_model.h", "avr_instance.h", "avr_fmi_api.h")
#: The FMI standard headers (third_party/fmi<version>/, with their license) each FMU ships.
FMI_HEADERS = {2: ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"),
               3: ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")}
THIRD_PARTY = NATIVE_SRC / "third_party"
#: FMI platform folder -> compiler target per FMI version ("linux": the host's compiler, the
#: others: compiler.CROSS_COMPILERS).
PLATFORMS = {
    2: {"linux64": "linux", "win64": "windows"},
    3: {"x86_64-linux": "linux", "aarch64-linux": "linux-aarch64", "x86_64-windows": "windows"},
}
LIBRARY_SUFFIX = {"linux": ".so", "linux-aarch64": ".so", "windows": ".dll"}
#: What each platform folder's binary runs on (the documentation's words).
PLATFORM_NAMES = {"linux64": "Linux x86-64", "win64": "Windows x86-64", "x86_64-linux": "Linux x86-64",
                  "aarch64-linux": "Linux aarch64 (ARM64)", "x86_64-windows": "Windows x86-64"}
GUID_HEADER = "sources/avr_guid.h"
#: Besides the options the FMU's sources declare (describe.COMPILER_OPTIONS).
WARNINGS = ("-Wall", "-Wextra", "-Werror", "-fvisibility=hidden")

log = logging.getLogger("avr_build")


def fmi_include(fmi_version: int) -> Path:
    """The folder of the FMI ``fmi_version`` standard headers."""
    return THIRD_PARTY / f"fmi{fmi_version}"


def cflags() -> tuple[str, ...]:
    return (*describe.COMPILER_OPTIONS.split(), *WARNINGS)


def fmu_name(fmi_version: int) -> str:
    return f"{MODEL_IDENTIFIER}_fmi{fmi_version}.fmu"


def sources(fmi_version: int) -> tuple[str, ...]:
    """The C files of the FMI ``fmi_version`` FMU (the rest of ``sources/`` are headers)."""
    return CORE_SOURCES + API_SOURCES[fmi_version]


def compile_command(target: str, c_files, out_name: str, extra_flags=()) -> list[str]:
    """Compiler command (run in the folder holding the sources) for target "linux",
    "linux-aarch64" or "windows"."""
    cc = compiler.compiler_for(target, "of the native FMUs")
    if target != "windows":
        return [cc, *cflags(), *extra_flags, "-shared", "-fPIC", "-Wl,--build-id=none",
                "-I.", *c_files, "-o", out_name, "-lm"]
    # --no-insert-timestamp: a PE header without the link time, so builds are byte-identical
    return [cc, *cflags(), *extra_flags, "-shared", "-static-libgcc",
            "-Wl,--no-insert-timestamp", "-I.", *c_files, "-o", out_name]


def compile_native(sources_dir: Path, fmi_version: int, target: str, out_path: Path, extra_flags=()) -> Path:
    """Compile the FMU's C sources in ``sources_dir`` into the shared library ``out_path``
    (``extra_flags`` after the usual ones, e.g. sanitizers for the tests)."""
    cmd = compile_command(target, sources(fmi_version), out_path.name, extra_flags)
    compiler.run(cmd, "the native FMU", cwd=sources_dir)
    shutil.move(str(sources_dir / out_path.name), out_path)
    return out_path


def source_entries(fmi_version: int, guid: str) -> dict[str, bytes]:
    """``sources/`` of the FMU: the C files and headers, the generated headers, the FMI headers."""
    files = {name: (NATIVE_SRC / name).read_bytes() for name in sources(fmi_version) + HEADERS}
    files.update({name: (fmi_include(fmi_version) / name).read_bytes() for name in FMI_HEADERS[fmi_version]})
    files["avr_vars.h"] = header.vars_header().encode()
    files["avr_guid.h"] = header.guid_header(guid).encode()
    if fmi_version == 3:
        files["buildDescription.xml"] = describe.build_description(MODEL_IDENTIFIER, sources(fmi_version))
    return {f"sources/{name}": data for name, data in files.items()}


def buildable_platforms(fmi_version: int, what: str | None = None) -> dict[str, str]:
    """The platforms of ``PLATFORMS[fmi_version]`` (folder -> target) whose compiler is installed;
    a warning names each one skipped, ``what`` (the FMU's file name; default: this regulator
    FMU's) and the Debian package that adds its cross compiler."""
    platforms = {}
    for platform, target in PLATFORMS[fmi_version].items():
        if target != "linux" and compiler.cross_compiler(target) is None:
            log.warning(compiler.skip_message(target, what or fmu_name(fmi_version)))
        else:
            platforms[platform] = target
    return platforms


def metadata_entries(fmi_version: int, guid: str, units: dict, default_experiment: dict,
                     platforms) -> dict[str, bytes]:
    """``modelDescription.xml`` and ``documentation/index.html`` (which names the binary
    ``platforms``, their folder names)."""
    return {
        "modelDescription.xml": describe.model_description(fmi_version, MODEL_IDENTIFIER, guid, sources(fmi_version),
                                                           units, default_experiment),
        "documentation/index.html": describe.documentation(
            fmi_version, MODEL_IDENTIFIER, [(p, PLATFORM_NAMES[p]) for p in platforms]).encode(),
    }


def _binaries(fmi_version: int, entries: dict[str, bytes], platforms: dict[str, str]) -> dict[str, bytes]:
    """The library of each of ``platforms`` (folder -> target), compiled from the ``sources/`` among ``entries``."""
    binaries = {}
    with tempfile.TemporaryDirectory(prefix="avr_native_") as tmp:
        src = Path(tmp) / "src"
        src.mkdir()
        for name, data in entries.items():
            if name.startswith("sources/"):
                (src / name[len("sources/"):]).write_bytes(data)
        for platform, target in platforms.items():
            lib = compile_native(src, fmi_version, target, Path(tmp) / f"{MODEL_IDENTIFIER}{LIBRARY_SUFFIX[target]}")
            binaries[f"binaries/{platform}/{lib.name}"] = lib.read_bytes()
    return binaries


def fmu_entries(fmi_version: int, units: dict, default_experiment: dict) -> dict[str, bytes]:
    """Every file of the FMI ``fmi_version`` native FMU, with the binaries of every platform
    whose compiler is installed (``buildable_platforms``).  The GUID (FMI 3.0:
    instantiationToken) is a hash of everything in the FMU except the binaries and the header
    holding the GUID, which are made from it."""
    platforms = buildable_platforms(fmi_version)

    def text_entries(guid: str) -> dict[str, bytes]:
        return {**metadata_entries(fmi_version, guid, units, default_experiment, platforms),
                **source_entries(fmi_version, guid)}

    guid = content_guid(hashlib.sha256(f"native fmi{fmi_version}\0".encode()), text_entries(PLACEHOLDER_GUID),
                        skip={GUID_HEADER})
    entries = text_entries(guid)
    entries.update(_binaries(fmi_version, entries, platforms))
    return entries
