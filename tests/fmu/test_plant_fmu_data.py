"""The CassiePlant FMU without its gait library cannot be instantiated, and says which file is
missing (issue 44: never a walk on the uncalibrated gait)."""
from __future__ import annotations

import os
import subprocess
import sys
import zipfile

from support.plant_fmu_support import built_plant_fmu

LIBRARY = "resources/cassie_plant_lib/plant/data/gait_library.json"
INSTANTIATE = """
import sys
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
folder = extract(sys.argv[1], unzipdir=sys.argv[2])
md = read_model_description(folder)
fmu = FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                instanceName="plant")
try:
    fmu.instantiate(loggingOn=True)
except Exception as exc:
    print("REFUSED", exc)
else:
    print("INSTANTIATED")
"""


def test_plant_fmu_without_gait_library_fails_to_instantiate_naming_the_file(tmp_path_factory, build_module,
                                                                             tmp_path):
    fmu = built_plant_fmu(tmp_path_factory, build_module)
    broken = tmp_path / "CassiePlant.fmu"
    with zipfile.ZipFile(fmu) as zin, zipfile.ZipFile(broken, "w", zipfile.ZIP_DEFLATED) as zout:
        assert LIBRARY in zin.namelist()
        for item in zin.infolist():
            if item.filename != LIBRARY:
                zout.writestr(item, zin.read(item))
    proc = subprocess.run([sys.executable, "-c", INSTANTIATE, str(broken), str(tmp_path / "x")], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300, env={**os.environ, "TMPDIR": str(tmp_path)})
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = proc.stdout + proc.stderr
    assert "REFUSED" in proc.stdout and "INSTANTIATED" not in proc.stdout, out[-3000:]
    assert str(tmp_path / "x" / LIBRARY) in out and "gait library" in out, out[-3000:]
