"""Build the regulator FMUs into ``dist/`` reproducibly, and ``dist/fmus.json`` listing them.

``AdaptiveVelocityRegulator.fmu`` (FMI 2.0 co-simulation, pythonfmu, the reference) and
``AdaptiveVelocityRegulatorNative_fmi2.fmu`` / ``_fmi3.fmu`` (the same regulator in C,
FMI 2.0 and FMI 3.0 from one source, linux and windows x86-64 binaries plus sources;
the win64 binaries need the MinGW-w64 cross compiler).

    python build.py [--out DIR]

Steps: pythonfmu packs the slave (``fmu_src/avr_slave.py``) with the numpy core;
then the model description is post-processed (units, ranges, default experiment,
a content-derived GUID, no generation time), a documentation page and a
``requirements.txt`` are added, the FMI guard (``fmu_src/guard/fmi2_guard.c``)
is compiled as the linux64 library the host loads (pythonfmu's own library
moves beside it as ``<id>_pythonfmu.so``), and the archive is written with
sorted entries and fixed timestamps, so two builds of the same sources give the
same sha256.  Prints the FMU's path and sha256.
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
PROJECT_FILES = (FMU_SRC / "avr_core.py", FMU_SRC / "avr_errors.py")
GUARD_SOURCE = FMU_SRC / "guard" / "fmi2_guard.c"
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


def _guard_header(root: ET.Element, guid: str) -> str:
    codes = {"Real": "R", "Integer": "I", "Boolean": "B", "String": "S"}
    rows = []
    for var in root.find("ModelVariables"):
        typed = var[0]
        lo, hi = typed.get("min"), typed.get("max")
        rows.append('    {"%s", \'%s\', \'%s\', \'%s\', %d, %s, %d, %s},  /* vr %s */' % (
            var.get("name"), codes[typed.tag], var.get("causality", "local")[0],
            var.get("variability", "continuous")[0], lo is not None, lo or "0", hi is not None, hi or "0",
            var.get("valueReference")))
        assert int(var.get("valueReference")) == len(rows) - 1, "value references must be 0..n-1 in order"
    return "\n".join([
        "/* Generated by build.py from modelDescription.xml: do not edit. */",
        "#pragma once",
        "typedef struct { const char *name; char type, causality, variability; int has_min; double min;"
        " int has_max; double max; } AvrVar;",
        f'#define AVR_GUID "{guid}"',
        f'#define AVR_INNER_LIBRARY "{MODEL_IDENTIFIER}_pythonfmu.so"',
        f"#define AVR_N_VARS {len(rows)}u",
        "static const AvrVar AVR_VARS[] = {", *rows, "};", ""])


def _compile_guard(header: str, out_path: Path) -> None:
    import fmpy

    include = Path(fmpy.__file__).parent / "c-code"  # the standard FMI 2.0 headers fmpy ships
    compiler = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
    if compiler is None:
        raise RuntimeError("build.py needs a C compiler (cc or gcc; set CC) to compile the FMI guard")
    with tempfile.TemporaryDirectory(prefix="avr_guard_") as tmp:
        (Path(tmp) / "avr_guard_vars.h").write_text(header)
        cmd = [compiler, "-shared", "-fPIC", "-O2", "-std=c11", "-Wall", "-Wextra", "-Werror", "-Wno-format-truncation",
               "-fvisibility=default", f"-ffile-prefix-map={tmp}=.", f"-ffile-prefix-map={REPO_ROOT}=.",
               "-Wl,--build-id=none", f"-I{tmp}", f"-I{include}", str(GUARD_SOURCE), "-o", str(out_path),
               "-ldl", "-lpthread", "-lm"]
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
fmi2Error and a log message naming the variable and its range; a refused call changes nothing. FMU state can be
saved, restored and serialized (all weights and memories). Requires Python 3 with numpy in the host process
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


def build_fmu(out_dir: Path = DEFAULT_OUT) -> Path:
    """Build ``<out_dir>/AdaptiveVelocityRegulator.fmu`` and return its path."""
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
    digest.update(GUARD_SOURCE.read_bytes())
    for name in sorted(entries):
        digest.update(name.encode() + b"\0" + entries[name])
    guid = "{" + str(uuid.uuid5(GUID_NAMESPACE, digest.hexdigest())) + "}"
    tree.getroot().set("guid", guid)

    with tempfile.TemporaryDirectory(prefix="avr_guard_out_") as tmp:
        guard_path = Path(tmp) / f"{MODEL_IDENTIFIER}.so"
        _compile_guard(_guard_header(tree.getroot(), guid), guard_path)
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


def build_all(out_dir: Path = DEFAULT_OUT) -> list[Path]:
    """Build the pythonfmu FMU and both native FMUs, and ``<out_dir>/fmus.json`` listing them."""
    built = [(build_fmu(out_dir), "python")] + [(build_native_fmu(v, out_dir), "native") for v in (2, 3)]
    listing = {"fmus": [fmu_entry(path, kind) for path, kind in built]}
    (Path(out_dir) / FMUS_JSON).write_text(json.dumps(listing, indent=2) + "\n")
    return [path for path, _ in built]


def sha256_of(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder (default: dist/)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    for path in build_all(args.out):
        print(path)
        print(f"sha256 {sha256_of(path)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
