"""In-process work for the sanitizer tests: on a regulator FMU (tests/native/test_native_hosts.py) state
round trips, every corrupted blob of tests/native/test_native_state.py, and 20 instances; on a
CommandSource FMU (tests/fmu/test_fmu_sanitize.py) 20 instances playing the schedule, every illegal
call of tests/fmu/test_command_source.py and a schedule that fails the instantiation; on a native
CassiePlant FMU (tests/native/test_native_plant.py) 4 instances walking, state round trips and
corrupted states refused.

    python sanitize_run.py FMU OTHER_FMU                       (exit 0 when every check held)
    python sanitize_run.py --command-source FMU_DIR FMI_VERSION
    python sanitize_run.py --plant FMU_DIR FMI_VERSION [TERRAIN_FIELD TERRAIN_PARAMS_JSON]
"""
import sys
from pathlib import Path

import numpy as np

TESTS = Path(__file__).parents[2]
# tests/ (the support package) and the layers whose tables this script reuses
sys.path[:0] = [str(TESTS), str(TESTS / "native"), str(TESTS / "fmu")]
from fmpy.fmi1 import FMICallException  # noqa: E402
from support.native_support import AnySlave, input_sequence  # noqa: E402
from test_native_state import _corruptions  # noqa: E402


def main(fmu, other_fmu):
    slaves = [AnySlave(fmu, name=f"i{i}").init(n_neurons=40 + i, seed=i, learning_rate=1e-4, learn_from_step=0)
              for i in range(20)]
    seq = input_sequence(60, seed=4)
    for k, u in enumerate(seq):
        for s in slaves:
            s.step(k, u)
    s = slaves[0]
    blob = s.serialize(s.get_state())
    other = AnySlave(other_fmu, name="other").init(n_neurons=40)
    refused = 0
    for name, bad in _corruptions(blob, other.serialize(other.get_state())):
        try:
            s.deserialize(bad)
        except FMICallException:
            refused += 1
        else:
            raise AssertionError(f"accepted a corrupted state: {name}")
    s.set_state(s.deserialize(blob))
    assert np.all(np.isfinite(s.step(len(seq), seq[0])))
    for slave in slaves + [other]:
        slave.close()
    print(f"refused {refused} corrupted states")


def command_source(fmu_dir, fmi):
    """The CommandSource FMU in this process: 20 instances stepping 400 times each, every illegal
    call of test_command_source.ILLEGAL (Error), and a malformed schedule (instantiation refused)."""
    import shutil
    import tempfile

    from support.command_source_driver import main as drive
    from test_command_source import ERROR, H, ILLEGAL, OK, START

    get = ["get", list(range(6))]
    long_run = START + [["step", k * H, H] for k in range(400)] + [get, ["terminate"], ["reset"], *START[1:],
                                                                   ["step", 0.0, H], get, ["free"]]
    for _ in range(20):
        results = drive(fmu_dir, fmi, long_run)["results"]
        assert all(r == OK for c, r in zip(long_run, results) if c is not get), results
        assert all(len(r) == 6 for c, r in zip(long_run, results) if c is get), results
    for name, before, illegal, _ in ILLEGAL:
        results = drive(fmu_dir, fmi, before + [illegal, ["free"]])["results"]
        assert results[len(before)] == ERROR, (name, results)
    with tempfile.TemporaryDirectory(dir=Path(fmu_dir).parent) as tmp:  # beside the FMU, under the test's tmp_path
        broken = Path(tmp) / "fmu"
        shutil.copytree(fmu_dir, broken)
        (broken / "resources" / "schedule.csv").write_text("time,vx_des\n0,x\n")
        assert drive(str(broken), fmi, [["instantiate"]])["results"] == [None]
    print(f"command source FMI {fmi}.0: 20 x {len(long_run)} calls, {len(ILLEGAL)} illegal calls refused, "
          "a malformed schedule refused")


def plant(fmu_dir, fmi, field=None, terrain_params=None):
    """The native CassiePlant FMU in this process: 4 instances walking 300 steps of 10 ms, a state
    taken, serialized, restored (same outputs after), and every byte-flipped state refused.  With
    a height-field file (and the terrain parameters it was made for): an instance walking on it,
    one walking the flat floor sloped both ways (the other parameters kept, the terrain off), one
    with a slope on the terrain refused, and the file cut short at every length class and with flipped
    bytes refused at initialization."""
    import json
    import random
    import tempfile

    from fmpy import read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave
    from fmpy.fmi3 import FMU3Slave

    md = read_model_description(fmu_dir)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outputs = [vr[n] for n in ("vx", "pitch", "roll", "plant_time")]
    h = 0.01

    def make(i, params=None):
        if fmi == 2:
            s = FMU2Slave(guid=md.guid, unzipDirectory=fmu_dir, modelIdentifier=md.coSimulation.modelIdentifier,
                          instanceName=f"p{i}")
            s.instantiate()
            s.setupExperiment(startTime=0.0)
            s.enterInitializationMode()
        else:
            s = FMU3Slave(guid=md.guid, unzipDirectory=fmu_dir, modelIdentifier=md.coSimulation.modelIdentifier,
                          instanceName=f"p{i}")
            s.instantiate()
            s.enterInitializationMode(startTime=0.0)
        # every setting is legal: a refusal below comes from ExitInitializationMode, not a setter
        settings = dict(vx_des=0.3 + 0.1 * (i % 4), **(params or {}))
        for name, value in settings.items():
            kind = type(value).__name__
            setter = {"str": s.setString, "int": s.setInteger if fmi == 2 else s.setInt32,
                      "float": s.setReal if fmi == 2 else s.setFloat64}[kind]
            try:
                setter([vr[name]], [value])
            except FMICallException as e:
                raise AssertionError(f"instance p{i}: setting {name} = {value!r} refused") from e
        s.exitInitializationMode()
        return s

    def walk(s, t, n):
        rows = []
        for _ in range(n):
            s.doStep(t, h)
            t += h
            rows.append((s.getReal if fmi == 2 else s.getFloat64)(outputs))
        return t, rows

    get_state, set_state = (("getFMUstate", "setFMUstate") if fmi == 2 else ("getFMUState", "setFMUState"))
    ser, deser = (("serializeFMUstate", "deSerializeFMUstate") if fmi == 2
                  else ("serializeFMUState", "deserializeFMUState"))
    slaves = [make(i) for i in range(4)]
    for s in slaves:
        t, _ = walk(s, 0.0, 300)
    s = slaves[0]
    state = getattr(s, get_state)()
    blob = getattr(s, ser)(state)
    _, first = walk(s, t, 50)
    getattr(s, set_state)(getattr(s, deser)(blob))
    _, again = walk(s, t, 50)
    assert again == first, "the restored state did not continue the run"
    rng, refused = random.Random(7), 0
    for _ in range(40):
        bad = bytearray(blob)
        bad[rng.randrange(len(bad))] ^= 1 << rng.randrange(8)
        try:
            getattr(s, set_state)(getattr(s, deser)(bytes(bad)))
        except FMICallException:
            refused += 1
        else:
            raise AssertionError("accepted a corrupted state")
    for s in slaves:
        s.terminate()
        s.freeInstance()
    note = ""
    if field is not None:
        params = dict(json.loads(terrain_params), terrain_field_file=field)
        s = make(9, params)
        walk(s, 0.0, 100)
        s.terminate()
        s.freeInstance()
        sloped = dict(params, terrain_max_height_m=0.0, floor_slope_deg=5.0, floor_cross_slope_deg=-4.0)
        del sloped["terrain_field_file"]
        s = make(29, sloped)
        walk(s, 0.0, 100)
        s.terminate()
        s.freeInstance()
        try:  # a slope tilts the flat floor: with a terrain it is refused at initialization
            make(30, dict(params, floor_slope_deg=5.0))
        except FMICallException:
            pass
        else:
            raise AssertionError("accepted floor_slope_deg = 5 with a terrain")
        data, bad_files = Path(field).read_bytes(), 0
        with tempfile.TemporaryDirectory(dir=Path(fmu_dir).parent) as tmp:  # under the test's tmp_path
            cuts = [data[:n] for n in (0, 10, 67, 68, 72, 1000, len(data) // 2, len(data) - 1)]
            flips = []
            for _ in range(12):
                b = bytearray(data)
                b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
                flips.append(bytes(b))
            for k, content in enumerate(cuts + flips + [data + b"\0" * 16]):
                path = Path(tmp) / f"bad{k}.cptf"
                path.write_bytes(content)
                try:
                    make(10 + k, dict(params, terrain_field_file=str(path)))
                except FMICallException:
                    bad_files += 1
                else:
                    raise AssertionError(f"accepted a bad height field ({len(content)} bytes)")
        note = f", a terrain walk, a sloped walk, a slope on the terrain and {bad_files} bad height fields refused"
    print(f"plant FMI {fmi}.0: 4 x 300 steps, a state round trip, {refused} corrupted states refused{note}")


if __name__ == "__main__":
    if sys.argv[1] == "--command-source":
        command_source(sys.argv[2], int(sys.argv[3]))
    elif sys.argv[1] == "--plant":
        plant(sys.argv[2], int(sys.argv[3]), *sys.argv[4:6])
    else:
        main(sys.argv[1], sys.argv[2])
