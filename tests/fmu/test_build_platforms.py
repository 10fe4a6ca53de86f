"""``python build.py`` on a machine without the cross compilers (MinGW-w64, aarch64 GCC).

The build finds every compiler by name on PATH (fmu_src/packing/compiler.py).  Here it
runs as a user runs it, in a process whose PATH holds every program of /usr/bin except the
cross toolchains: it must build every FMU with the host's binaries, name each skipped
platform and the Debian package that adds it, list only the platforms built in
``fmus.json`` and the FMUs' documentation, and exit 0.  (With the cross compilers installed,
as in CI, every platform is built and checked: tests/support/native/test_native_fmu.py, test_native_aarch64.py.)
"""
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path
from support.paths import REPO_ROOT

CROSS_PREFIXES = ("x86_64-w64-mingw32-", "aarch64-linux-gnu-")


def _path_without_cross_compilers(folder: Path) -> str:
    """A folder of links to every program in /usr/bin except the cross toolchains."""
    folder.mkdir()
    for program in Path("/usr/bin").iterdir():
        if not program.name.startswith(CROSS_PREFIXES):
            (folder / program.name).symlink_to(program)
    return str(folder)


def test_build_without_cross_compilers_builds_the_host_binaries_and_exits_0(tmp_path):
    out = tmp_path / "dist"
    env = {**os.environ, "PATH": _path_without_cross_compilers(tmp_path / "bin")}
    proc = subprocess.run([sys.executable, "build.py", "--out", str(out)], cwd=REPO_ROOT, env=env,
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    skipped = [line for line in proc.stderr.splitlines() if "skipped the" in line]
    for fmu, platforms in (("fmi2", ["Windows x86-64"]), ("fmi3", ["Linux aarch64", "Windows x86-64"])):
        for platform, package in ((p, "gcc-aarch64-linux-gnu" if "aarch64" in p else "gcc-mingw-w64-x86-64")
                                  for p in platforms):
            assert any(f"{platform} binaries of AdaptiveVelocityRegulatorNative_{fmu}.fmu" in line
                       and f"apt-get install {package}" in line for line in skipped), proc.stderr
    # the regulator's and the CommandSource's FMI 2.0 and 3.0 FMUs, and the native plant's Windows binaries
    assert len(skipped) == 8, skipped
    listing = {e["file"]: e["platforms"] for e in json.loads((out / "fmus.json").read_text())["fmus"]}
    assert listing["AdaptiveVelocityRegulatorNative_fmi2.fmu"] == ["linux64"]
    assert listing["AdaptiveVelocityRegulatorNative_fmi3.fmu"] == ["x86_64-linux"]
    for name, folder in (("fmi2", "linux64"), ("fmi3", "x86_64-linux")):
        with zipfile.ZipFile(out / f"AdaptiveVelocityRegulatorNative_{name}.fmu") as z:
            listed = z.read("documentation/index.html").decode().split("<h2>Platforms</h2>")[1].split("</ul>")[0]
        assert listed.count("<li>") == 1 and f"<code>binaries/{folder}/</code>" in listed
    assert (out / "CassieAVR.ssp").is_file()
    for name, folder in (("fmi2", "linux64"), ("fmi3", "x86_64-linux")):  # the other native FMUs: the same rule
        with zipfile.ZipFile(out / f"CommandSource_{name}.fmu") as z:
            assert sorted({n.split("/")[1] for n in z.namelist() if n.startswith("binaries/")}) == [folder]
    cross_check = out / "cross-check" / "fmus" / "2.0" / "cs"
    assert sorted(p.name for p in cross_check.iterdir()) == ["linux64"]  # no win64 entry without its binary
