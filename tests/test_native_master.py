"""Our master runs the native FMI 2.0 FMU (``--regulator native``): the same closed loop as
the numpy core in-process, to the cross-check's tolerance."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from scenarios import master, spec


def test_master_native_regulator_matches_the_core_in_process(native_fmus, tmp_path):
    s = spec.override(spec.resolve_targets(["mass_20kg"])[0], duration_s=3.0)
    native = master.run_arm(s, "adaptive", master.make_regulator("native", native_fmus[2], unpack_dir=tmp_path))
    core = master.run_arm(s, "adaptive", master.make_regulator("inprocess"))
    assert len(native.rows) == len(core.rows) == 600 and not native.fell
    for name in native.rows.dtype.names:
        # 1e-9 (the cross-check's bound): the cores differ by the summation order of dot products only
        np.testing.assert_allclose(native.rows[name], core.rows[name], rtol=0, atol=1e-9, err_msg=name)


def test_cli_runs_the_native_fmu(native_fmus, tmp_path):
    out = tmp_path / "runs"
    proc = subprocess.run([sys.executable, "-m", "scenarios", "run", "nominal", "--regulator", "native",
                           "--fmu", str(native_fmus[2]), "--duration", "1", "--out", str(out)],
                          capture_output=True, text=True, cwd=Path(__file__).parents[1])  # MENAGERIE_ROOT may be relative
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "nominal" / "summary.json").read_text())
    assert summary["regulator"] == "native" and summary["status"] == "complete"
