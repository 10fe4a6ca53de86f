"""Build the regulator FMUs into ``dist/`` reproducibly, and ``dist/fmus.json`` listing them.

``AdaptiveVelocityRegulator.fmu`` (FMI 2.0 co-simulation, pythonfmu, the reference) and
``AdaptiveVelocityRegulatorNative_fmi2.fmu`` / ``_fmi3.fmu`` (the same regulator in C,
FMI 2.0 and FMI 3.0 from one source, linux and windows x86-64 binaries plus sources;
the win64 binaries need the MinGW-w64 cross compiler).

    python build.py [--out DIR] [--sanitize]

Steps: pythonfmu packs the slave (``fmu_src/avr_slave.py``) with the numpy core;
then the model description is post-processed (units, ranges, default experiment,
a content-derived GUID, no generation time), a documentation page and a
``requirements.txt`` are added, the FMI guard (``fmu_src/guard/*.c``)
is compiled as the linux64 library the host loads (pythonfmu's own library
moves beside it as ``<id>_pythonfmu.so``), and the archive is written with
sorted entries and fixed timestamps, so two builds of the same sources give the
same sha256.  Prints the FMU's path and sha256.  ``--sanitize`` compiles the guard
with AddressSanitizer + UndefinedBehaviorSanitizer instead (for the ``sanitize`` tests).
Temporary folders are removed when the build ends, also when it fails.
"""
from __future__ import annotations

import argparse
import hashlib
import html
import io
import json
import logging
import os
import shutil
import subprocess
import sys
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parent
FMU_SRC = REPO_ROOT / "fmu_src"
SLAVE_SCRIPT = FMU_SRC / "avr_slave.py"
#: The regulator FMU's modules besides the slave script (flat in resources/); the plant FMU
#: vendors them too (``_vendor_plant``): its slave uses avr_slavebase, its core avr_specs.
PROJECT_FILES = tuple(FMU_SRC / f"avr_{name}.py" for name in (
    "core", "errors", "fmustate", "network", "params", "regulator", "slavebase", "specs", "statebytes"))
GUARD_DIR = FMU_SRC / "guard"
#: The FMI guard's C sources (guard.h is included by each).
GUARD_SOURCES = tuple(sorted(GUARD_DIR.glob("*.c")))
MODEL_IDENTIFIER = "AdaptiveVelocityRegulator"
DEFAULT_OUT = REPO_ROOT / "dist"
#: Fixed zip timestamp (the earliest a zip can hold) so builds are byte-identical.
ZIP_EPOCH = (1980, 1, 1, 0, 0, 0)
GUID_NAMESPACE = uuid.UUID("6f1c2a52-1d0e-4c59-9a57-4a7f2a1b0c01")
UNITS = {  # name -> SI base-unit exponents
    "m/s": {"m": "1", "s": "-1"},
    "rad": {"rad": "1"},
    "rad/s": {"rad": "1", "s": "-1"},
    "s": {"s": "1"},
}
DEFAULT_EXPERIMENT = {"startTime": "0", "stopTime": "10", "stepSize": "0.005"}
REQUIREMENTS = "numpy>=1.24\n"

log = logging.getLogger("avr_build")


def _specs():
    sys.path.insert(0, str(REPO_ROOT))
    try:
        from fmu_src.avr_core import INPUT_SPECS, OUTPUT_SPECS, PARAM_SPECS
    finally:
        sys.path.remove(str(REPO_ROOT))
    return (*PARAM_SPECS, *INPUT_SPECS, *OUTPUT_SPECS)


def _fmt(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


def _postprocess_model_description(xml_bytes: bytes, specs) -> ET.ElementTree:
    root = ET.fromstring(xml_bytes)
    root.attrib.pop("generationDateAndTime", None)
    root.set("guid", "{00000000-0000-0000-0000-000000000000}")  # replaced once the content hash is known
    by_name = {spec.name: spec for spec in specs}
    children = list(root)
    for child in children:
        root.remove(child)
    units = ET.Element("UnitDefinitions")
    for name, exponents in UNITS.items():
        unit = ET.SubElement(units, "Unit", name=name)
        ET.SubElement(unit, "BaseUnit", exponents)
    ordered = []
    for child in children:  # schema order: CoSimulation, UnitDefinitions, ..., LogCategories, DefaultExperiment
        if child.tag == "DefaultExperiment":
            continue
        ordered.append(child)
        if child.tag == "CoSimulation":
            ordered.append(units)
        if child.tag == "LogCategories":
            ordered.append(ET.Element("DefaultExperiment", DEFAULT_EXPERIMENT))
    for child in ordered:
        root.append(child)
    for var in root.find("ModelVariables"):
        spec = by_name[var.get("name")]
        typed = var[0]
        if spec.type == "Real" and spec.unit in UNITS:
            typed.set("unit", spec.unit)
        if spec.type in ("Real", "Integer"):
            if spec.min is not None:
                typed.set("min", _fmt(spec.min))
            if spec.max is not None:
                typed.set("max", _fmt(spec.max))
    ET.indent(root)
    return ET.ElementTree(root)


#: pythonfmu 0.7.0's linux64 library frees its static ``pyState`` shared_ptr at exit and then
#: runs its destructor ``finalizePythonInterpreter``, which resets the same (already
#: destroyed) shared_ptr: a use-after-free that corrupts the heap at process exit (valgrind:
#: "Invalid read ... inside a block free'd"; a C host aborts every time, a Python host
#: sometimes).  The static destructor already releases the state, so the fix is to make
#: ``finalizePythonInterpreter`` return at once: after its ``endbr64``, a ``ret``.
EXIT_BUG_SYMBOL = b"finalizePythonInterpreter"
EXIT_BUG_PROLOGUE = bytes.fromhex("f30f1efa55")  # endbr64; push %rbp -- the 0.7.0 build we patch
EXIT_BUG_PATCH = bytes.fromhex("f30f1efac3")  # endbr64; ret


def _elf_symbol_file_offset(data: bytes, symbol: bytes) -> int:
    """File offset of a dynamic symbol's code in an ELF64 little-endian shared library."""
    import struct

    if data[:4] != b"\x7fELF" or data[4] != 2 or data[5] != 1:
        raise RuntimeError("pythonfmu's linux64 library is not an ELF64 little-endian file")
    e_phoff, e_shoff = struct.unpack_from("<QQ", data, 0x20)
    e_phentsize, e_phnum, e_shentsize, e_shnum = struct.unpack_from("<HHHH", data, 0x36)
    sections = [struct.unpack_from("<IIQQQQIIQQ", data, e_shoff + i * e_shentsize) for i in range(e_shnum)]
    dynsym = next(s for s in sections if s[1] == 11)  # SHT_DYNSYM
    strtab = sections[dynsym[6]]  # sh_link: its string table
    value = None
    for off in range(dynsym[4], dynsym[4] + dynsym[5], 24):
        st_name, _, _, _, st_value, _ = struct.unpack_from("<IBBHQQ", data, off)
        start = strtab[4] + st_name
        if data[start:data.index(b"\0", start)] == symbol:
            value = st_value
            break
    if value is None:
        raise RuntimeError(f"symbol {symbol.decode()} not found in pythonfmu's linux64 library")
    for i in range(e_phnum):
        p_type, _, p_offset, p_vaddr, _, p_filesz, _, _ = struct.unpack_from("<IIQQQQQQ", data, e_phoff + i * e_phentsize)
        if p_type == 1 and p_vaddr <= value < p_vaddr + p_filesz:  # PT_LOAD
            return value - p_vaddr + p_offset
    raise RuntimeError(f"symbol {symbol.decode()} is not in a loaded segment")


def patch_pythonfmu_exit_bug(data: bytes) -> bytes:
    """pythonfmu 0.7.0's linux64 library without its use-after-free at process exit."""
    offset = _elf_symbol_file_offset(data, EXIT_BUG_SYMBOL)
    found = data[offset:offset + len(EXIT_BUG_PROLOGUE)]
    if found == EXIT_BUG_PATCH:
        return data
    if found != EXIT_BUG_PROLOGUE:
        raise RuntimeError(f"unexpected code at {EXIT_BUG_SYMBOL.decode()} ({found.hex()}): a pythonfmu build this "
                           "script does not know; check whether its exit-time use-after-free is fixed, then update build.py")
    return data[:offset] + EXIT_BUG_PATCH + data[offset + len(EXIT_BUG_PATCH):]


def _guard_header(root: ET.Element, guid: str, slave_module: str) -> str:
    """The guard's generated table (avr_guard_vars.h): every variable by value reference, the
    fixed parameters, the log categories, the GUID and the slave module's name."""
    codes = {"Real": "R", "Integer": "I", "Boolean": "B", "String": "S"}
    rows, fixed = [], []
    for var in root.find("ModelVariables"):
        typed = var[0]
        lo, hi, start = typed.get("min"), typed.get("max"), typed.get("start", "0")
        start = "0" if typed.tag == "String" else {"true": "1", "false": "0"}.get(start, start)
        causality, variability = var.get("causality", "local"), var.get("variability", "continuous")
        rows.append('    {"%s", \'%s\', \'%s\', \'%s\', %d, %s, %d, %s, %s},  /* vr %s */' % (
            var.get("name"), codes[typed.tag], causality[0], variability[0], lo is not None, lo or "0",
            hi is not None, hi or "0", start, var.get("valueReference")))
        assert int(var.get("valueReference")) == len(rows) - 1, "value references must be 0..n-1 in order"
        if causality == "parameter" and variability == "fixed" and typed.tag != "String":  # the slave checks strings
            fixed.append(var.get("valueReference"))
    categories = [c.get("name") for c in root.find("LogCategories")]
    return "\n".join([
        "/* Generated by build.py from modelDescription.xml: do not edit. */",
        "#pragma once",
        "typedef struct { const char *name; char type, causality, variability; int has_min; double min;"
        " int has_max; double max; double start; } AvrVar;",
        f'#define AVR_GUID "{guid}"',
        f'#define AVR_INNER_LIBRARY "{MODEL_IDENTIFIER}_pythonfmu.so"',
        f'#define AVR_SLAVE_MODULE "{slave_module}"',
        f"#define AVR_N_VARS {len(rows)}u",
        "static const AvrVar AVR_VARS[] __attribute__((unused)) = {", *rows, "};",
        f"#define AVR_N_FIXED {len(fixed)}u  /* fixed parameters: an FMU state must match their values */",
        "static const unsigned AVR_FIXED_VRS[] __attribute__((unused)) = {" + ", ".join(fixed) + "};",
        f"#define AVR_N_LOG_CATEGORIES {len(categories)}u",
        "static const char *const AVR_LOG_CATEGORIES[] __attribute__((unused)) = {"
        + ", ".join(f'"{c}"' for c in categories) + "};", ""])


#: Extra compiler flags of a sanitizer build (``build_fmu(sanitize=True)``, ``python build.py --sanitize``):
#: AddressSanitizer and UndefinedBehaviorSanitizer, every finding fatal, good stack traces.
SANITIZE_FLAGS = ("-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer", "-g")


def _compile_guard(header: str, out_path: Path, sanitize: bool = False) -> None:
    import fmpy

    include = Path(fmpy.__file__).parent / "c-code"  # the standard FMI 2.0 headers fmpy ships
    compiler = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
    if compiler is None:
        raise RuntimeError("build.py needs a C compiler (cc or gcc; set CC) to compile the FMI guard")
    with tempfile.TemporaryDirectory(prefix="avr_guard_") as tmp:
        (Path(tmp) / "avr_guard_vars.h").write_text(header)
        optimise = ["-O1", *SANITIZE_FLAGS] if sanitize else ["-O2"]
        cmd = [compiler, "-shared", "-fPIC", *optimise, "-std=c11", "-Wall", "-Wextra", "-Werror",
               "-Wno-format-truncation", "-fvisibility=hidden", f"-ffile-prefix-map={tmp}=.",
               f"-ffile-prefix-map={REPO_ROOT}=.", "-Wl,--build-id=none", f"-I{tmp}", f"-I{include}",
               *[str(p) for p in GUARD_SOURCES], "-o", str(out_path), "-ldl", "-lpthread", "-lm"]
        result = subprocess.run(cmd, capture_output=True, text=True)
        if result.returncode != 0:
            raise RuntimeError(f"compiling the FMI guard failed:\n{' '.join(cmd)}\n{result.stderr}")


def _documentation(specs) -> str:
    rows = "\n".join(
        f"<tr><td>{s.name}</td><td>{s.causality}</td><td>{s.type}</td><td>{s.variability}</td>"
        f"<td>{html.escape(s.unit)}</td><td>{_fmt(s.default)}</td>"
        f"<td>{'' if s.min is None else _fmt(s.min)}</td><td>{'' if s.max is None else _fmt(s.max)}</td>"
        f"<td>{html.escape(s.description)}</td></tr>" for s in specs)
    return f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>{MODEL_IDENTIFIER}</title></head><body>
<h1>{MODEL_IDENTIFIER}</h1>
<p>Adaptive velocity regulator for 3D bipedal walking, after Castillo, Weng, Stewart, Zhang and Hereid,
"Velocity Regulation of 3D Bipedal Walking Robots with Uncertain Dynamics Through Adaptive Neural Network
Controller" (IROS 2020). A nominal walking controller tracks joint virtual constraints
<code>y = q - (y_d(tau) + delta_y)</code>; this FMU computes the offsets <code>delta_y</code>.</p>
<h2>Method</h2>
<ul>
<li>Longitudinal: <code>Kp_x (vx[k]-vx_des) + Kd_x (vx[k]-vx[k-1]) + Psi_x</code> on swing hip pitch
(Psi also on swing knee); updated when <code>step_index</code> changes.</li>
<li>Lateral: the same with <code>vy</code> on swing hip roll (Psi also on stance hip roll).</li>
<li>Torso: <code>Kp_pitch (pitch-pitch_des) + Kd_pitch pitch_rate + Psi</code> on stance hip pitch
(Psi also on stance knee); roll on stance hip roll.</li>
<li>Each Psi is a one-hidden-layer network of <code>n_neurons</code> LIF-rate neurons with fixed random
encoders (seeded); output weights start at zero and learn online by the delta rule
<code>W += -learning_rate * dt / n_neurons * E h^T</code>, <code>E = desired - actual</code>.
<code>psi_gain_*</code> scale each output (0 switches it off); <code>adaptation_enabled=false</code> gives the
classic PD regulator exactly.</li>
</ul>
<h2>FMI behaviour</h2>
<p>Co-simulation, any communication step &gt; 0. Calls the FMI 2.0 state machine forbids, sets of outputs or of
fixed parameters after initialization, NaN/inf values and values outside [min, max] are refused with
fmi2Error and a log message naming the variable and its range; a refused call changes nothing. The six offsets
are clipped to &plusmn;<code>delta_limit_rad</code>. FMU state can be saved, restored and serialized (all weights
and memories); a serialized state carries a CRC-64, the FMU's GUID and the fixed parameters' values, and a
corrupted, truncated, foreign or non-finite state, or one saved with other fixed parameters, is refused with
fmi2Error naming why. Requires Python 3 with numpy in the host process
(see <code>resources/requirements.txt</code>).</p>
<h2>Variables</h2>
<table border="1"><tr><th>name</th><th>causality</th><th>type</th><th>variability</th><th>unit</th>
<th>default</th><th>min</th><th>max</th><th>description</th></tr>
{rows}
</table></body></html>
"""


def _write_zip(entries: dict[str, bytes], path: Path) -> None:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for name in sorted(entries):
            info = zipfile.ZipInfo(name, date_time=ZIP_EPOCH)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.create_system = 3  # unix
            info.external_attr = (0o755 if name.endswith(".so") else 0o644) << 16
            archive.writestr(info, entries[name], compresslevel=9)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".fmu.tmp")
    tmp.write_bytes(buffer.getvalue())
    tmp.replace(path)


def build_fmu(out_dir: Path = DEFAULT_OUT, sanitize: bool = False) -> Path:
    """Build ``<out_dir>/AdaptiveVelocityRegulator.fmu`` and return its path.

    ``sanitize``: compile the FMI guard with AddressSanitizer and UndefinedBehaviorSanitizer
    (``SANITIZE_FLAGS``), for tests only: a host must then preload libasan (see the README).
    """
    from pythonfmu.builder import FmuBuilder

    specs = _specs()
    with tempfile.TemporaryDirectory(prefix="avr_fmu_") as tmp:
        raw = FmuBuilder.build_FMU(SLAVE_SCRIPT, dest=Path(tmp), project_files=list(PROJECT_FILES),
                                   canGetAndSetFMUstate=True, canSerializeFMUstate=True)
        with zipfile.ZipFile(raw) as archive:
            entries = {name: archive.read(name) for name in archive.namelist() if not name.endswith("/")}
    tree = _postprocess_model_description(entries.pop("modelDescription.xml"), specs)
    entries["documentation/index.html"] = _documentation(specs).encode("utf-8")
    entries["resources/requirements.txt"] = REQUIREMENTS.encode("utf-8")
    pythonfmu_linux = entries.pop(f"binaries/linux64/{MODEL_IDENTIFIER}.so")
    entries[f"binaries/linux64/{MODEL_IDENTIFIER}_pythonfmu.so"] = patch_pythonfmu_exit_bug(pythonfmu_linux)

    # GUID: a hash of everything but the guard library (which embeds the GUID) and the GUID itself.
    digest = hashlib.sha256()
    digest.update(ET.tostring(tree.getroot()))
    for source in (*GUARD_SOURCES, GUARD_DIR / "guard.h"):
        digest.update(source.read_bytes())
    for name in sorted(entries):
        digest.update(name.encode() + b"\0" + entries[name])
    guid = "{" + str(uuid.uuid5(GUID_NAMESPACE, digest.hexdigest())) + "}"
    tree.getroot().set("guid", guid)

    with tempfile.TemporaryDirectory(prefix="avr_guard_out_") as tmp:
        guard_path = Path(tmp) / f"{MODEL_IDENTIFIER}.so"
        slave_module = entries["resources/slavemodule.txt"].decode("utf-8").strip()
        _compile_guard(_guard_header(tree.getroot(), guid, slave_module), guard_path, sanitize)
        entries[f"binaries/linux64/{MODEL_IDENTIFIER}.so"] = guard_path.read_bytes()

    xml_out = io.BytesIO()
    tree.write(xml_out, encoding="UTF-8", xml_declaration=True)
    entries["modelDescription.xml"] = xml_out.getvalue()
    fmu_path = Path(out_dir) / f"{MODEL_IDENTIFIER}.fmu"
    _write_zip(entries, fmu_path)
    log.info("built %s", fmu_path)
    return fmu_path


# --------------------------------------------------------------------------------------
# Native FMUs (C, no Python): FMI 2.0 and FMI 3.0 from one source, fmu_src/native/
# --------------------------------------------------------------------------------------
NATIVE_SRC = FMU_SRC / "native"
NATIVE_MODEL_IDENTIFIER = "AdaptiveVelocityRegulatorNative"
NATIVE_CORE_SOURCES = ("avr_model.c", "avr_instance.c", "avr_state.c")
NATIVE_API_SOURCES = {2: ("fmi2_api.c",), 3: ("fmi3_api.c", "fmi3_refused.c")}
NATIVE_HEADERS = ("avr_types.h", "avr_model.h", "avr_instance.h")
FMI_HEADERS = {2: ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"),
               3: ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")}
#: FMI platform folder -> (compiler, library suffix, extra flags) per FMI version.
NATIVE_PLATFORMS = {
    2: {"linux64": "linux", "win64": "windows"},
    3: {"x86_64-linux": "linux", "x86_64-windows": "windows"},
}
MINGW_CC = "x86_64-w64-mingw32-gcc"  # Debian package gcc-mingw-w64-x86-64
#: Besides the options the FMU's sources declare (fmu_src/native/describe.py COMPILER_OPTIONS).
NATIVE_WARNINGS = ("-Wall", "-Wextra", "-Werror", "-fvisibility=hidden")
FMUS_JSON = "fmus.json"


def _native_modules():
    """fmu_src.native's ``header`` and ``describe`` (build.py also runs without the package installed)."""
    sys.path.insert(0, str(REPO_ROOT))
    try:
        from fmu_src.native import describe, header
    finally:
        sys.path.remove(str(REPO_ROOT))
    return header, describe


def native_cflags() -> tuple[str, ...]:
    return (*_native_modules()[1].COMPILER_OPTIONS.split(), *NATIVE_WARNINGS)


def native_fmu_name(fmi_version: int) -> str:
    return f"{NATIVE_MODEL_IDENTIFIER}_fmi{fmi_version}.fmu"


def native_sources(fmi_version: int) -> tuple[str, ...]:
    """The C files of the FMI ``fmi_version`` FMU (the rest of ``sources/`` are headers)."""
    return NATIVE_CORE_SOURCES + NATIVE_API_SOURCES[fmi_version]


def _native_compile_command(target: str, sources, out_name: str, extra_flags=()) -> list[str]:
    """Compiler command (run in the folder holding the sources) for target "linux" or "windows"."""
    if target == "linux":
        compiler = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
        if compiler is None:
            raise RuntimeError("build.py needs a C compiler (cc or gcc; set CC) for the native FMUs")
        return [compiler, *native_cflags(), *extra_flags, "-shared", "-fPIC", "-Wl,--build-id=none",
                "-I.", *sources, "-o", out_name, "-lm"]
    compiler = shutil.which(MINGW_CC)
    if compiler is None:
        raise RuntimeError(f"build.py needs the MinGW-w64 cross compiler {MINGW_CC} for the win64 binaries "
                           "(Debian: apt-get install gcc-mingw-w64-x86-64)")
    # --no-insert-timestamp: a PE header without the link time, so builds are byte-identical
    return [compiler, *native_cflags(), *extra_flags, "-shared", "-static-libgcc", "-Wl,--no-insert-timestamp", "-I.", *sources,
            "-o", out_name]


def compile_native(sources_dir: Path, fmi_version: int, target: str, out_path: Path, extra_flags=()) -> Path:
    """Compile the FMU's C sources in ``sources_dir`` into the shared library ``out_path``
    (``extra_flags`` after the usual ones, e.g. sanitizers for the tests)."""
    cmd = _native_compile_command(target, native_sources(fmi_version), out_path.name, extra_flags)
    result = subprocess.run(cmd, cwd=sources_dir, capture_output=True, text=True)
    if result.returncode != 0:
        raise RuntimeError(f"compiling the native FMU failed:\n{' '.join(cmd)}\n{result.stderr}")
    shutil.move(str(sources_dir / out_path.name), out_path)
    return out_path


def _native_source_entries(fmi_version: int, guid: str) -> dict[str, bytes]:
    """``sources/`` of the FMU: the C files and headers, the generated headers, the FMI headers."""
    header, describe = _native_modules()
    files = {name: (NATIVE_SRC / name).read_bytes() for name in native_sources(fmi_version) + NATIVE_HEADERS}
    files.update({name: (NATIVE_SRC / "include" / name).read_bytes() for name in FMI_HEADERS[fmi_version]})
    files["avr_vars.h"] = header.vars_header().encode()
    files["avr_guid.h"] = header.guid_header(guid).encode()
    if fmi_version == 3:
        files["buildDescription.xml"] = describe.build_description(NATIVE_MODEL_IDENTIFIER,
                                                                   native_sources(fmi_version))
    return {f"sources/{name}": data for name, data in files.items()}


def _native_metadata(fmi_version: int, guid: str) -> dict[str, bytes]:
    describe = _native_modules()[1]
    return {
        "modelDescription.xml": describe.model_description(fmi_version, NATIVE_MODEL_IDENTIFIER, guid,
                                                           native_sources(fmi_version), UNITS, DEFAULT_EXPERIMENT),
        "documentation/index.html": describe.documentation(fmi_version, NATIVE_MODEL_IDENTIFIER).encode(),
    }


def build_native_fmu(fmi_version: int, out_dir: Path = DEFAULT_OUT) -> Path:
    """Build ``<out_dir>/AdaptiveVelocityRegulatorNative_fmi<2|3>.fmu`` (linux and windows x86-64) reproducibly.

    The GUID (FMI 3.0: instantiationToken) is a hash of everything in the FMU except the
    binaries and the header holding the GUID, which are made from it."""
    placeholder = "{00000000-0000-0000-0000-000000000000}"
    digest = hashlib.sha256(f"native fmi{fmi_version}\0".encode())
    for name, data in sorted({**_native_metadata(fmi_version, placeholder),
                              **_native_source_entries(fmi_version, placeholder)}.items()):
        if name != "sources/avr_guid.h":
            digest.update(name.encode() + b"\0" + data)
    guid = "{" + str(uuid.uuid5(GUID_NAMESPACE, digest.hexdigest())) + "}"
    entries = {**_native_metadata(fmi_version, guid), **_native_source_entries(fmi_version, guid)}
    with tempfile.TemporaryDirectory(prefix="avr_native_") as tmp:
        src = Path(tmp) / "src"
        src.mkdir()
        for name, data in entries.items():
            if name.startswith("sources/"):
                (src / name[len("sources/"):]).write_bytes(data)
        for platform, target in NATIVE_PLATFORMS[fmi_version].items():
            suffix = ".so" if target == "linux" else ".dll"
            lib = compile_native(src, fmi_version, target, Path(tmp) / f"{NATIVE_MODEL_IDENTIFIER}{suffix}")
            entries[f"binaries/{platform}/{lib.name}"] = lib.read_bytes()
    fmu_path = Path(out_dir) / native_fmu_name(fmi_version)
    _write_zip(entries, fmu_path)
    log.info("built %s", fmu_path)
    return fmu_path


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


def sha256_of(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# =====================================================================================
# CassiePlant FMU and the CassieAVR system (SSP and OSP) -- issue 10
# =====================================================================================
PLANT_SLAVE_SCRIPT = FMU_SRC / "cassie_plant_slave.py"
PLANT_IDENTIFIER = "CassiePlant"
#: The plant package and its project imports travel in resources/<PLANT_LIB>/ (see the slave).
PLANT_LIB = "cassie_plant_lib"
PLANT_CORE = Path("plant") / "fmu_core.py"
PLANT_DATA = (Path("plant") / "data" / "gait_library.json",)
PROJECT_PACKAGES = ("plant", "fmu_src")
PLANT_UNITS = {"1": {}, "m": {"m": "1"}, "N": {"kg": "1", "m": "1", "s": "-2"}, "kg": {"kg": "1"},
               "deg": {"rad": "1", "factor": repr(3.141592653589793 / 180)}}
PLANT_REQUIREMENTS = "numpy>=1.24\nmujoco>=3.2\n"
MODEL_LICENSES = REPO_ROOT / "plant" / "model_licenses"  # menagerie.txt, osu.txt (texts, not models)


def _repo_module(name: str):
    """A module of this repository (imported with the repository on sys.path for the call)."""
    import importlib

    sys.path.insert(0, str(REPO_ROOT))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(REPO_ROOT))


def _plant_core():
    return _repo_module("plant.fmu_core")


def _project_import(node, package: str) -> str | None:
    """The package-relative module an absolute ``from plant|fmu_src... import`` names, else None."""
    import ast

    if not isinstance(node, ast.ImportFrom) or node.level or not node.module:
        return None
    top, _, rest = node.module.partition(".")
    if top not in PROJECT_PACKAGES:
        return None
    return ("." if top == package else ".." + top + ("." if rest else "")) + rest


def _vendored_source(path: Path) -> tuple[str, list[Path]]:
    """The module's text with its project imports made package-relative, and the files it imports."""
    import ast

    rel = path.relative_to(REPO_ROOT)
    lines = path.read_text().splitlines(keepends=True)
    needed = []
    for node in ast.walk(ast.parse("".join(lines))):
        if isinstance(node, ast.Import) and any(a.name.split(".")[0] in PROJECT_PACKAGES for a in node.names):
            raise RuntimeError(f"{rel}:{node.lineno}: use 'from ... import' for project modules (vendoring)")
        target = _project_import(node, rel.parts[0])
        if target is None:
            continue
        line = lines[node.lineno - 1]
        if f"from {node.module} import" not in line:
            raise RuntimeError(f"{rel}:{node.lineno}: cannot rewrite the import of {node.module}")
        lines[node.lineno - 1] = line.replace(f"from {node.module} import", f"from {target} import", 1)
        module = REPO_ROOT.joinpath(*node.module.split("."))
        if module.with_suffix(".py").is_file():
            needed.append(module.with_suffix(".py"))
        else:  # a package: the modules imported from it by name
            needed += [module / f"{a.name}.py" for a in node.names if (module / f"{a.name}.py").is_file()]
    return "".join(lines), needed


def _vendor_plant(lib: Path) -> None:
    """Copy plant/fmu_core.py and every project module it needs (imports made relative) to ``lib``."""
    todo, done = [REPO_ROOT / PLANT_CORE, *PROJECT_FILES], set()
    while todo:
        path = todo.pop()
        if path in done:
            continue
        done.add(path)
        text, needed = _vendored_source(path)
        (lib / path.relative_to(REPO_ROOT)).parent.mkdir(parents=True, exist_ok=True)
        (lib / path.relative_to(REPO_ROOT)).write_text(text)
        todo.extend(needed)
    for package in PROJECT_PACKAGES:
        (lib / package / "__init__.py").write_text(f'"""The {package} modules the CassiePlant FMU needs."""\n')
    (lib / "__init__.py").write_text('"""CassiePlant FMU: the plant package, loaded by cassie_plant_slave."""\n')
    for data in PLANT_DATA:
        (lib / data).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(REPO_ROOT / data, lib / data)


def _copy_models(models: Path) -> None:
    """Menagerie's agility_cassie (mujoco-menagerie / MENAGERIE_ROOT) and OSU's model, with licenses."""
    import mujoco_menagerie

    model = _repo_module("plant.model")
    menagerie = Path(mujoco_menagerie.get(model.MENAGERIE_ROBOT).xml(model.MENAGERIE_ENTRY)).parent
    shutil.copytree(menagerie, models / "menagerie" / menagerie.name)
    shutil.copyfile(MODEL_LICENSES / "menagerie.txt", models / "menagerie" / "LICENSE")
    osu = model.osu_model_path()
    if not osu.is_file():
        log.warning("OSU model not found at %s (set CASSIE_OSU_XML): the FMU's model='osu' will be refused", osu)
        return
    (models / "osu").mkdir(parents=True)
    shutil.copyfile(osu, models / "osu" / "cassie.xml")
    shutil.copytree(osu.parent / "cassie-stl-meshes", models / "osu" / "cassie-stl-meshes")
    shutil.copyfile(MODEL_LICENSES / "osu.txt", models / "osu" / "LICENSE")


def _plant_model_description(xml_bytes: bytes, specs) -> ET.ElementTree:
    """The regulator's post-processing plus the plant's units."""
    tree = _postprocess_model_description(xml_bytes, specs)
    root = tree.getroot()
    units = root.find("UnitDefinitions")
    for name, exponents in PLANT_UNITS.items():
        ET.SubElement(ET.SubElement(units, "Unit", name=name), "BaseUnit", exponents)
    by_name = {spec.name: spec for spec in specs}
    for var in root.find("ModelVariables"):
        spec = by_name[var.get("name")]
        if spec.type == "Real" and spec.unit in PLANT_UNITS:
            var[0].set("unit", spec.unit)
    ET.indent(root)
    return tree


def _plant_documentation(specs) -> str:
    table = _documentation(specs)
    table = table[table.index("<h2>Variables</h2>"):]
    return f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>{PLANT_IDENTIFIER}</title></head><body>
<h1>{PLANT_IDENTIFIER}</h1>
<p>MuJoCo Cassie biped (Menagerie's agility_cassie or Oregon State's model, both in
<code>resources/{PLANT_LIB}/models</code> with their licenses) with a nominal HZD-style walking controller:
0.5 ms plant step, joint PD servos inside MuJoCo, starts from rest in the standing pose, stands, shifts its
weight and walks at the commanded speed. Connect the AdaptiveVelocityRegulator FMU name to name: this FMU's
outputs vx, vy, pitch, roll, pitch_rate, roll_rate, step_index are its inputs, its six delta_* outputs are
this FMU's inputs.</p>
<h2>FMI behaviour</h2>
<p>Co-simulation; communication steps must be whole multiples of 0.5 ms (else fmi2Error naming the step).
A fall sets the output <code>fell</code>; the simulation goes on. Calls the state machine forbids, sets of
outputs or of fixed parameters after initialization, NaN/inf or out-of-range values: fmi2Error, logged,
no effect. Invalid parameter combinations (the plant's own validation, every problem named with its range)
make fmi2ExitInitializationMode return fmi2Error and stay in initialization mode. FMU state: MuJoCo's full
integration state and the controller's memory; restore-then-continue is bit-identical. Needs Python 3 with
numpy and mujoco in the host (<code>resources/requirements.txt</code>); linux64.</p>
{table}"""


def _plant_guard_header(root: ET.Element, guid: str, plant_step_s: float) -> str:
    """The regulator's table generator for the plant: its inner library, its slave, the 0.5 ms step quantum."""
    header = _guard_header(root, guid, PLANT_SLAVE_SCRIPT.stem)
    header = header.replace(f'"{MODEL_IDENTIFIER}_pythonfmu.so"', f'"{PLANT_IDENTIFIER}_pythonfmu.so"')
    return header + f"#define AVR_STEP_QUANTUM {plant_step_s!r}\n"


def _plant_entries(tmp: Path, specs) -> tuple[dict, ET.ElementTree]:
    from pythonfmu.builder import FmuBuilder

    lib = tmp / "stage" / PLANT_LIB
    _vendor_plant(lib)
    _copy_models(lib / "models")
    raw = FmuBuilder.build_FMU(PLANT_SLAVE_SCRIPT, dest=tmp / "raw", project_files=[lib],
                               canGetAndSetFMUstate=True, canSerializeFMUstate=True)
    with zipfile.ZipFile(raw) as archive:
        entries = {name: archive.read(name) for name in archive.namelist() if not name.endswith("/")}
    if f"binaries/linux64/{PLANT_IDENTIFIER}.so" not in entries:
        import pythonfmu

        raise RuntimeError(f"pythonfmu came from {Path(pythonfmu.__file__).parent}, which has no binaries (an FMU's "
                           "resources copy, imported after a pythonfmu FMU was loaded): build in a fresh process")
    for name in [n for n in entries if n.startswith("binaries/") and not n.startswith("binaries/linux64/")]:
        del entries[name]  # the guard is built for linux64 only: without it a refusal could only be fmi2Fatal
    tree = _plant_model_description(entries.pop("modelDescription.xml"), specs)
    entries["documentation/index.html"] = _plant_documentation(specs).encode("utf-8")
    entries["resources/requirements.txt"] = PLANT_REQUIREMENTS.encode("utf-8")
    inner = entries.pop(f"binaries/linux64/{PLANT_IDENTIFIER}.so")
    entries[f"binaries/linux64/{PLANT_IDENTIFIER}_pythonfmu.so"] = patch_pythonfmu_exit_bug(inner)
    return entries, tree


def build_plant_fmu(out_dir: Path = DEFAULT_OUT, sanitize: bool = False) -> Path:
    """Build ``<out_dir>/CassiePlant.fmu`` (FMI 2.0 co-simulation, linux64) and return its path.

    ``sanitize``: the guard with AddressSanitizer and UBSan, as for ``build_fmu`` (tests only).
    """
    core = _plant_core()
    with tempfile.TemporaryDirectory(prefix="cassie_plant_fmu_") as tmp:
        entries, tree = _plant_entries(Path(tmp), core.SPECS)
    digest = hashlib.sha256(ET.tostring(tree.getroot()))
    for source in (*GUARD_SOURCES, GUARD_DIR / "guard.h"):
        digest.update(source.read_bytes())
    for name in sorted(entries):
        digest.update(name.encode() + b"\0" + entries[name])
    guid = "{" + str(uuid.uuid5(GUID_NAMESPACE, "CassiePlant:" + digest.hexdigest())) + "}"
    tree.getroot().set("guid", guid)
    with tempfile.TemporaryDirectory(prefix="cassie_plant_guard_") as tmp:
        guard_path = Path(tmp) / f"{PLANT_IDENTIFIER}.so"
        _compile_guard(_plant_guard_header(tree.getroot(), guid, core.PLANT_STEP_S), guard_path, sanitize)
        entries[f"binaries/linux64/{PLANT_IDENTIFIER}.so"] = guard_path.read_bytes()
    xml_out = io.BytesIO()
    tree.write(xml_out, encoding="UTF-8", xml_declaration=True)
    entries["modelDescription.xml"] = xml_out.getvalue()
    fmu_path = Path(out_dir) / f"{PLANT_IDENTIFIER}.fmu"
    _write_zip(entries, fmu_path)
    log.info("built %s", fmu_path)
    return fmu_path


def build_ssp(out_dir: Path, plant_fmu: Path, regulator_fmu: Path) -> Path:
    """Write ``<out_dir>/CassieAVR.ssp``: both FMUs wired name to name, the nominal parameter sets and a
    30 s, 5 ms default experiment (the structure is ``scenarios/system.py``'s); reproducible zip."""
    system = _repo_module("scenarios.system")
    path = Path(out_dir) / f"{system.SYSTEM_NAME}.ssp"
    _write_zip(system.ssp_entries(Path(plant_fmu), Path(regulator_fmu)), path)
    return path


def build_osp(out_dir: Path, plant_fmu: Path, regulator_fmu: Path) -> Path:
    """Write the folder ``<out_dir>/CassieAVR_osp/``: OspSystemStructure.xml beside copies of both FMUs."""
    system = _repo_module("scenarios.system")
    folder = Path(out_dir) / f"{system.SYSTEM_NAME}_osp"
    folder.mkdir(parents=True, exist_ok=True)
    for fmu in (plant_fmu, regulator_fmu):
        shutil.copyfile(fmu, folder / Path(fmu).name)
    (folder / "OspSystemStructure.xml").write_bytes(system.osp_system_structure(Path(plant_fmu), Path(regulator_fmu)))
    return folder

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
