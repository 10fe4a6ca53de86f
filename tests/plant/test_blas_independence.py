"""The loop's numbers do not depend on the BLAS kernel or on numpy's SIMD dispatch.

OpenBLAS (numpy's BLAS/LAPACK, built with DYNAMIC_ARCH) picks its kernels for the CPU at
load time; ``OPENBLAS_CORETYPE`` forces another CPU's kernels, so one machine can play
several.  numpy picks its SIMD loops (AVX2, AVX-512, ...) per CPU too;
``NPY_DISABLE_CPU_FEATURES`` turns the dispatched ones off.  Each setting below is first
shown to change numpy's own results here (raw 3x3 products and a LAPACK polynomial fit;
float64 ``exp``/``log``), then the suite's runs under that setting must write the same
``timeseries.csv``, byte for byte, as under the CPU's own choices.  The runs call the
regulator core in-process (the FMUs wrap the same BLAS-free cores).

Not covered (see the README): glibc's libm has CPU-specific variants too (with and without
FMA3), which differ in the last bit for roughly 1 argument in 1000; MuJoCo's own step calls
it, so a CPU without FMA3 (Intel before Haswell, AMD before Piledriver) takes other bits.
Every CPU with FMA3 takes the same variant.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from support.paths import REPO_ROOT as REPO

#: Two OpenBLAS kernel sets whose 3x3 double products differ (FMA kernels vs SSE2/AVX ones),
#: both of which the x86-64 DYNAMIC_ARCH builds accept.
BLAS_CORETYPES = ("Haswell", "Sandybridge")
#: numpy's dispatch groups above its x86-64 baseline (X86_V2): AVX2+FMA3 and AVX-512 loops off.
NPY_DISABLED = "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"
#: A short terrain walk: the weight shift ends at 1.5 s, so 3 s has several steps on
#: uneven ground, long enough for a 1-ulp difference to reach the printed digits (it
#: does in the first rows on a BLAS-dependent loop).
TERRAIN_SCENARIO, TERRAIN_S = "terrain_mass_com", 3.0

#: Prints one hash of numpy results that depend on the BLAS kernel (matrix products, a
#: LAPACK least-squares fit) and one of results that depend on numpy's SIMD dispatch
#: (float64 exp and log of many arguments).
_PROBE = r"""
import hashlib, numpy as np
rng = np.random.default_rng(1)
a, b = rng.standard_normal((500, 3, 3)), rng.standard_normal((500, 3))
blas = [a[i] @ b[i] for i in range(500)] + [np.polyfit(np.linspace(-2.6, -0.7, 40), rng.standard_normal(40), 5)]
x = rng.standard_normal(100000)
simd = [np.exp(x), np.log(np.abs(x) + 0.1)]
print(hashlib.sha1(np.concatenate(blas).tobytes()).hexdigest(), hashlib.sha1(np.concatenate(simd).tobytes()).hexdigest())
"""


def _env(tmp_path: Path, **settings: str) -> dict[str, str]:
    """The test's environment without any kernel choice of the caller's, plus ``settings``;
    temporary files go to ``tmp_path``."""
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES")}
    env.setdefault("MENAGERIE_ROOT", str(REPO.parent / "shared" / "cassie" / "menagerie"))
    (tmp_path / "tmp").mkdir(exist_ok=True)
    env["TMPDIR"] = str(tmp_path / "tmp")
    env.update(settings)
    return env


def _probe(tmp_path: Path, **settings: str) -> tuple[str, str]:
    proc = subprocess.run([sys.executable, "-c", _PROBE], env=_env(tmp_path, **settings), capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    blas, simd = proc.stdout.split()
    return blas, simd


def _variants(tmp_path: Path) -> dict[str, dict[str, str]]:
    """The kernel settings to compare with the CPU's own choice, by label, each shown to change
    numpy's results here (a setting that changes nothing on this machine would prove nothing)."""
    base = _probe(tmp_path)
    variants = {f"blas_{c}": {"OPENBLAS_CORETYPE": c} for c in BLAS_CORETYPES}
    if all(_probe(tmp_path, **s)[0] == base[0] for s in variants.values()):
        pytest.skip(f"OPENBLAS_CORETYPE={'/'.join(BLAS_CORETYPES)} select no other BLAS results here "
                    "(numpy's OpenBLAS is not a DYNAMIC_ARCH build): nothing to compare")
    settings = {"NPY_DISABLE_CPU_FEATURES": NPY_DISABLED}
    if _probe(tmp_path, **settings)[1] != base[1]:  # a CPU with AVX2 or AVX-512: numpy dispatches
        variants["npy_baseline_simd"] = settings
    return variants


def _run(tmp_path: Path, label: str, names: list[str], settings: dict[str, str], extra=()) -> Path:
    out = tmp_path / label
    cmd = [sys.executable, "-m", "scenarios", "run", *names, "--regulator", "inprocess", "--no-plots",
           "--out", str(out), *extra]
    proc = subprocess.run(cmd, cwd=REPO, env=_env(tmp_path, **settings), capture_output=True, text=True,
                          timeout=3600)
    assert proc.returncode == 0, f"{label}: {proc.stderr[-3000:]}"
    return out


def _assert_same_timeseries(reference: Path, other: Path, label: str) -> int:
    files = sorted(p.relative_to(reference) for p in reference.rglob("timeseries.csv"))
    assert files, f"no timeseries.csv under {reference}"
    for rel in files:
        a, b = (reference / rel).read_bytes(), (other / rel).read_bytes()
        if a != b:
            line = next(i for i, (x, y) in enumerate(zip(a.splitlines(), b.splitlines())) if x != y)
            pytest.fail(f"{rel} differs under {label} from line {line + 1} on")
    return len(files)


#: Prints one hash of the sloped floor's orientation for 400 slopes in the language's range.
_SLOPES = r"""
import hashlib, numpy as np
from plant.perturbation import slope_quat
rng = np.random.default_rng(2)
quats = [slope_quat(float(s), float(c)) for s, c in rng.uniform(-15.0, 15.0, (400, 2))]
print(hashlib.sha1(np.concatenate(quats).tobytes()).hexdigest())
"""


def test_floor_slopes_same_bits_under_other_kernels(tmp_path):
    """The sloped floor's orientation does not follow numpy's SIMD loops (np.tan and np.arccos
    round ~0.6 % and ~10 % of such arguments differently with AVX-512 on) nor BLAS."""
    def run(settings):
        proc = subprocess.run([sys.executable, "-c", _SLOPES], cwd=REPO, env=_env(tmp_path, **settings),
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        return proc.stdout.strip()
    reference = run({})
    for label, settings in _variants(tmp_path).items():
        assert run(settings) == reference, label


def test_terrain_walk_same_bits_under_other_kernels(tmp_path):
    """A terrain walk with a model change (both arms, the adaptive regulator and PD only)
    writes the same time series under each kernel setting."""
    quick = ["--duration", str(TERRAIN_S)]
    reference = _run(tmp_path, "auto", [TERRAIN_SCENARIO], {}, quick)
    for label, settings in _variants(tmp_path).items():
        _assert_same_timeseries(reference, _run(tmp_path, label, [TERRAIN_SCENARIO], settings, quick), label)


@pytest.mark.long
def test_whole_suite_same_bits_under_other_kernels(tmp_path):
    """Every suite scenario (terrain, turning, pushes, the RL-HZD policy, ...) at full length
    writes the same time series with other BLAS kernels and without numpy's dispatched SIMD
    loops, both at once (two suite runs instead of one per setting)."""
    reference = _run(tmp_path, "auto", ["all"], {}, ["--jobs", "2"])
    variants = _variants(tmp_path)
    # Sandybridge: the kernel set whose 3x3 products differ from the FMA kernels' (see the probe).
    combined = {**variants.get("npy_baseline_simd", {}), **variants[f"blas_{BLAS_CORETYPES[-1]}"]}
    other = _run(tmp_path, "other_kernels", ["all"], combined, ["--jobs", "2"])
    label = " ".join(f"{k}={v!r}" for k, v in combined.items())
    assert _assert_same_timeseries(reference, other, label) == len(list(REPO.glob("scenarios/suite/*.toml")))
