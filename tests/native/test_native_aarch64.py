"""The native FMI 3.0 FMU's Linux aarch64 binary (ARM robot computers, Jetson-class boards).

build.py cross-compiles it (Debian gcc-aarch64-linux-gnu); here it is checked as an ARM
machine would use it: an aarch64 ELF library needing only libc and libm, loaded by the plain
C FMI 3.0 host (cross-compiled too) under qemu-aarch64 (Debian qemu-user), computing the
shipped x86-64 binary's outputs byte for byte, which are the numpy core's to the last bit.
The FMU's documentation names the platforms it carries binaries for.
"""
import subprocess
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description

from support.native_support import (AARCH64_CC, CC, READELF, c_host_outputs, c_host_script, compile_host, core_outputs,
                            input_sequence, require, run_host)

PARAMS = {"n_neurons": 500, "seed": 3, "learning_rate": 1e-4, "psi_gain_stance_knee": 0.0}
N_STEPS = 400
AARCH64_LIBRARY = "binaries/aarch64-linux/AdaptiveVelocityRegulatorNative.so"
X86_64_LIBRARY = "binaries/x86_64-linux/AdaptiveVelocityRegulatorNative.so"


def test_fmi3_fmu_carries_an_aarch64_linux_library(native_fmus, tmp_path):
    require(AARCH64_CC)  # build.py skips the platform without it (tests/fmu/test_build_platforms.py)
    with zipfile.ZipFile(native_fmus[3]) as z:
        assert AARCH64_LIBRARY in z.namelist()
        library = tmp_path / "aarch64.so"
        library.write_bytes(z.read(AARCH64_LIBRARY))
        doc = z.read("documentation/index.html").decode()
    header = subprocess.run([str(require(READELF)), "-h", str(library)], capture_output=True, text=True).stdout
    assert "AArch64" in header and "DYN (Shared object file)" in header, header
    dynamic = subprocess.run([str(READELF), "-d", str(library)], capture_output=True, text=True).stdout
    needed = {line.split("[")[1].rstrip("]") for line in dynamic.splitlines() if "(NEEDED)" in line}
    assert needed <= {"libm.so.6", "libc.so.6"}, needed
    for folder in ("aarch64-linux", "x86_64-linux", "x86_64-windows"):
        assert f"<code>binaries/{folder}/</code>" in doc
    assert "<code>sources/</code> build the library" in doc


def test_aarch64_library_under_qemu_gives_the_x86_64_bits(native_fmus, tmp_path):
    fmu = native_fmus[3]
    sequence = input_sequence(N_STEPS, seed=8)
    script = tmp_path / "script.txt"
    script.write_text(c_host_script(fmu, PARAMS, sequence))
    token = read_model_description(str(fmu)).guid
    outputs = {}
    with zipfile.ZipFile(fmu) as z:
        assert AARCH64_LIBRARY in z.namelist(), "no Linux aarch64 library in the FMI 3.0 FMU"
        for cpu, name, compiler in (("x86_64", X86_64_LIBRARY, CC), ("aarch64", AARCH64_LIBRARY, AARCH64_CC)):
            library = tmp_path / f"{cpu}.so"
            library.write_bytes(z.read(name))
            host = compile_host(compiler, 3, tmp_path / f"host_{cpu}")
            outputs[cpu] = run_host(host, cpu, library, token, script)
    assert len(outputs["aarch64"].splitlines()) == N_STEPS
    assert outputs["aarch64"] == outputs["x86_64"]  # %.17g of every output: the same doubles
    # ... which are the numpy core's (no libm function in the numerics, no FMA contraction)
    np.testing.assert_array_equal(c_host_outputs(outputs["aarch64"]), core_outputs(sequence, **PARAMS))


@pytest.mark.parametrize("fmi", [2, 3])
def test_documentation_names_the_platforms_with_binaries(native_fmus, fmi):
    with zipfile.ZipFile(native_fmus[fmi]) as z:
        folders = sorted({n.split("/")[1] for n in z.namelist() if n.startswith("binaries/") and n.count("/") == 2})
        doc = z.read("documentation/index.html").decode()
    listed = doc.split("<h2>Platforms</h2>")[1].split("</ul>")[0]
    assert sorted(listed.count(f"<code>binaries/{f}/</code>") for f in folders) == [1] * len(folders)
    assert listed.count("<li>") == len(folders)  # and no other
