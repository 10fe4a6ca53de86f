"""What only the native FMUs promise: no Python in any binary, and build.py's fmus.json.

The compliance rules every regulator FMU keeps (validation, state machine, refusals, state
round trips, instances, reproducible build) are in tests/fmu/test_fmu_compliance.py, run on the
pythonfmu FMU and on both native FMUs.
"""
import hashlib
import json
import subprocess
import zipfile
from pathlib import Path

import pytest

from fmu_src.core.avr_profiles import PROFILES
from support.native_support import AARCH64_CC, MINGW_CC, MINGW_OBJDUMP, READELF, require

FMI = pytest.mark.parametrize("fmi", [2, 3])


@FMI
def test_no_python_in_any_binary(native_fmus, fmi, tmp_path):
    with zipfile.ZipFile(native_fmus[fmi]) as z:
        binaries = {n: z.read(n) for n in z.namelist() if n.startswith("binaries/")}
    for name, data in binaries.items():
        assert b"python" not in data.lower() and b"numpy" not in data.lower(), name
        path = tmp_path / Path(name).name
        path.write_bytes(data)
        if name.endswith(".so"):
            out = subprocess.run([str(require(READELF)), "-d", str(path)], capture_output=True, text=True).stdout
            needed = {line.split("[")[1].rstrip("]") for line in out.splitlines() if "(NEEDED)" in line}
            assert needed <= {"libm.so.6", "libc.so.6"}, needed
        else:
            out = subprocess.run([str(require(MINGW_OBJDUMP)), "-p", str(path)], capture_output=True, text=True).stdout
            dlls = {line.split()[-1].lower() for line in out.splitlines() if "DLL Name:" in line}
            assert dlls <= {"kernel32.dll", "msvcrt.dll"}, dlls


def test_build_all_writes_fmus_json_listing_every_fmu_built(built_all):
    require(MINGW_CC), require(AARCH64_CC)  # without them build.py skips their platforms (test_build_platforms.py)
    built = built_all.built
    paths = [p for p in built if p.suffix == ".fmu"]
    profiles = [p for p in built if p.suffix == ".ssv"]
    assert {p.name for p in built} - {p.name for p in paths + profiles} == {"CassieAVR.ssp", "CassieAVR_osp", "CassieAVRNative.ssp"}
    assert sorted(p.stem for p in profiles) == sorted(PROFILES) and all(p.parent == built_all.dist / "profiles" for p in profiles)
    assert all(p.parent == built_all.dist for p in built if p not in profiles)
    listing = json.loads((built_all.dist / "fmus.json").read_text())["fmus"]
    assert [e["file"] for e in listing] == [p.name for p in paths] and all(p.is_file() for p in paths)
    assert [(e["fmiVersion"], e["modelIdentifier"], e["implementation"], e["platforms"]) for e in listing] == [
        ("2.0", "AdaptiveVelocityRegulator", "python", ["linux64", "win64"]),
        ("2.0", "AdaptiveVelocityRegulatorNative", "native", ["linux64", "win64"]),
        ("3.0", "AdaptiveVelocityRegulatorNative", "native", ["aarch64-linux", "x86_64-linux", "x86_64-windows"]),
        ("2.0", "CassiePlant", "python", ["linux64"]),
        ("2.0", "CommandSource", "native", ["linux64", "win64"]),
        ("3.0", "CommandSource", "native", ["aarch64-linux", "x86_64-linux", "x86_64-windows"]),
        ("2.0", "CassiePlantNative", "native", ["linux64", "win64"]),
        ("3.0", "CassiePlantNative", "native", ["x86_64-linux", "x86_64-windows"])]
    assert all(e["sha256"] == hashlib.sha256(p.read_bytes()).hexdigest() for e, p in zip(listing, paths))
