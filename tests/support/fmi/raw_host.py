"""Call the FMU's library directly through ctypes, with what no polite importer passes.

NULL and non-UTF-8 strings, odd resource URIs, unknown log categories, foreign,
truncated and corrupted FMU states, calls after a fatal error.  Each case runs in a
process of its own, so that a crash shows as a failed test, not a dead pytest:

    python raw_host.py FMU_DIR CASE < JSON_ARGS

prints one JSON object (the case's results, with every log message the FMU sent).
FMU_DIR is the extracted FMU.  The serialized-state layout used to craft blobs is the
one documented in fmu_src/regulator_fmu/guard/guard_state.c; ``crc64`` is an independent bitwise
CRC-64/XZ.
"""
import ctypes
import gc
import json
import math
import random
import struct
import sys
import zlib
from ctypes import POINTER, byref, c_char, c_char_p, c_double, c_int, c_size_t, c_uint, c_void_p
from pathlib import Path

from fmpy import read_model_description
from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                       fmi2CallbackLoggerTYPE)
from fmpy.logging import addLoggerProxy

OK, WARNING, DISCARD, ERROR, FATAL = range(5)
H = 0.005
#: offsets in the guard's serialized state (guard_state.c)
TIME_OFFSET, GUID_OFFSET, GUID_FIELD = 8, 20, 40

_libc = ctypes.CDLL(None)
_libc.calloc.restype = c_void_p
_libc.calloc.argtypes = [c_size_t, c_size_t]
_libc.free.argtypes = [c_void_p]


def crc64(data: bytes) -> int:
    """CRC-64/XZ (reflected ECMA-182 polynomial, init and final xor all ones), bit by bit."""
    crc = 0xFFFFFFFFFFFFFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ (0xC96C5795D7870F42 if crc & 1 else 0)
    return crc ^ 0xFFFFFFFFFFFFFFFF


def reseal(blob: bytes) -> bytes:
    """``blob`` with its trailing CRC-64 recomputed (to test the checks behind the checksum)."""
    return blob[:-8] + struct.pack("<Q", crc64(blob[:-8]))


def split_state(blob: bytes):
    """(the guard's header, the slave's blob) of a serialized state."""
    n_fixed = struct.unpack_from("<I", blob, 60)[0]
    head_bytes = 64 + 12 * n_fixed + 8
    return blob[:head_bytes], blob[head_bytes:-8]


def forge(blob: bytes, edit_json=None, edit_core=None, json_value=None) -> bytes:
    """``blob`` with the slave's JSON changed (in place by edit_json, or replaced by json_value)
    and/or its core bytes (edit_core), every length and both checksums made right again: a state
    only a deliberate forger could write, to test the checks behind the checksums."""
    head, slave = split_state(blob)
    _, version, n_text, n_core = struct.unpack_from("<4sIII", slave)
    scalars = json.loads(slave[16:16 + n_text])
    core = slave[16 + n_text:16 + n_text + n_core]
    if edit_json is not None:
        edit_json(scalars)
    if json_value is not None:
        scalars = json_value
    if edit_core is not None:
        core = edit_core(core)
    text = json.dumps(scalars, sort_keys=True).encode()
    body = struct.pack("<4sIII", b"AVRS", version, len(text), len(core)) + text + core
    slave = body + struct.pack("<I", zlib.crc32(body))
    out = head[:-8] + struct.pack("<Q", len(slave)) + slave
    return out + struct.pack("<Q", crc64(out))


class RawFmu:
    """The guard library, its functions typed for ctypes, and a logger that keeps every message."""

    def __init__(self, fmu_dir):
        self.dir = Path(fmu_dir)
        self.md = read_model_description(str(fmu_dir))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.types = {v.name: v.type for v in self.md.modelVariables}
        self.lib = ctypes.CDLL(str(self.dir / "binaries" / "linux64" / f"{self.md.coSimulation.modelIdentifier}.so"))
        self.log = []
        self._callbacks = fmi2CallbackFunctions()
        self._callbacks.logger = fmi2CallbackLoggerTYPE(self._logger)
        self._callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(_libc.calloc)
        self._callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(_libc.free)
        addLoggerProxy(byref(self._callbacks))  # formats the variadic arguments before Python sees them
        f = self.lib
        f.fmi2Instantiate.restype = c_void_p
        f.fmi2Instantiate.argtypes = [c_char_p, c_int, c_char_p, c_char_p, POINTER(fmi2CallbackFunctions), c_int, c_int]
        f.fmi2FreeInstance.argtypes = [c_void_p]
        f.fmi2FreeInstance.restype = None
        f.fmi2SetDebugLogging.argtypes = [c_void_p, c_int, c_size_t, POINTER(c_char_p)]
        f.fmi2SetupExperiment.argtypes = [c_void_p, c_int, c_double, c_double, c_int, c_double]
        for name in ("fmi2EnterInitializationMode", "fmi2ExitInitializationMode", "fmi2Terminate", "fmi2Reset"):
            getattr(f, name).argtypes = [c_void_p]
        f.fmi2SetReal.argtypes = [c_void_p, POINTER(c_uint), c_size_t, POINTER(c_double)]
        f.fmi2GetReal.argtypes = [c_void_p, POINTER(c_uint), c_size_t, POINTER(c_double)]
        f.fmi2SetInteger.argtypes = [c_void_p, POINTER(c_uint), c_size_t, POINTER(c_int)]
        f.fmi2SetString.argtypes = [c_void_p, POINTER(c_uint), c_size_t, POINTER(c_char_p)]
        f.fmi2DoStep.argtypes = [c_void_p, c_double, c_double, c_int]
        f.fmi2GetFMUstate.argtypes = [c_void_p, POINTER(c_void_p)]
        f.fmi2SetFMUstate.argtypes = [c_void_p, c_void_p]
        f.fmi2FreeFMUstate.argtypes = [c_void_p, POINTER(c_void_p)]
        f.fmi2SerializedFMUstateSize.argtypes = [c_void_p, c_void_p, POINTER(c_size_t)]
        f.fmi2SerializeFMUstate.argtypes = [c_void_p, c_void_p, POINTER(c_char), c_size_t]
        f.fmi2DeSerializeFMUstate.argtypes = [c_void_p, POINTER(c_char), c_size_t, POINTER(c_void_p)]

    def _logger(self, env, name, status, category, message):
        self.log.append([status, (category or b"").decode("utf-8", "replace"), message.decode("utf-8", "replace")])

    def uri(self):
        return (self.dir / "resources").as_uri().encode()

    def instantiate(self, name=b"raw", guid=None, uri=None, callbacks=True):
        guid = self.md.guid.encode() if guid is None else guid
        uri = self.uri() if uri is None else uri
        return self.lib.fmi2Instantiate(name, 1, guid, uri, byref(self._callbacks) if callbacks else None, 0, 0)

    def set(self, c, name, value):
        vr = (c_uint * 1)(self.vr[name])
        if self.types[name] == "Integer":
            return self.lib.fmi2SetInteger(c, vr, 1, (c_int * 1)(value))
        return self.lib.fmi2SetReal(c, vr, 1, (c_double * 1)(value))

    def init(self, c, **params):
        statuses = [self.set(c, k, v) for k, v in params.items()]
        statuses += [self.lib.fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0), self.lib.fmi2EnterInitializationMode(c),
                     self.lib.fmi2ExitInitializationMode(c)]
        assert statuses == [OK] * len(statuses), (statuses, self.log[-3:])
        return c

    def step(self, c, k, vx=0.8):
        """One step from k*H with a persistent speed error (so the networks learn); returns the outputs."""
        assert self.set(c, "vx", vx) == OK and self.set(c, "vx_des", 0.5) == OK and self.set(c, "step_index", 1 + k // 50) == OK
        assert self.lib.fmi2DoStep(c, k * H, H, 1) == OK, self.log[-3:]
        names = [v.name for v in self.md.modelVariables if v.causality == "output"]
        out = (c_double * len(names))()
        assert self.lib.fmi2GetReal(c, (c_uint * len(names))(*[self.vr[n] for n in names]), len(names), out) == OK
        return list(out)

    def get_state(self, c):
        state = c_void_p()
        assert self.lib.fmi2GetFMUstate(c, byref(state)) == OK
        return state

    def serialize(self, c, state=None):
        own = state is None
        state = self.get_state(c) if own else state
        size = c_size_t()
        assert self.lib.fmi2SerializedFMUstateSize(c, state, byref(size)) == OK
        buffer = (c_char * size.value)()
        assert self.lib.fmi2SerializeFMUstate(c, state, buffer, size.value) == OK
        if own:
            self.lib.fmi2FreeFMUstate(c, byref(state))
        return bytes(buffer)

    def deserialize(self, c, blob):
        """(status, state); a refused blob leaves no state."""
        state = c_void_p()
        buffer = ctypes.create_string_buffer(blob, len(blob)) if blob else (c_char * 1)()
        status = self.lib.fmi2DeSerializeFMUstate(c, buffer, len(blob), byref(state))
        return status, state

    def restore(self, c, blob):
        """Deserialize and set; returns the two statuses."""
        status, state = self.deserialize(c, blob)
        if status != OK:
            return [status]
        statuses = [status, self.lib.fmi2SetFMUstate(c, state)]
        self.lib.fmi2FreeFMUstate(c, byref(state))
        return statuses

    def messages(self, since=0):
        return [m for _, _, m in self.log[since:]]


# ---- cases ------------------------------------------------------------------------------
def case_instantiate(fmu, attempts):
    """attempts: [label, name, guid, uri], each hex-encoded bytes, None for NULL, or "default"
    for the well-formed value.  A NULL result must come with a logged reason; a component
    must work (initialize, step, terminate)."""
    def arg(value, default):
        return default if value == "default" else None if value is None else bytes.fromhex(value)

    results = {}
    for label, name, guid, uri in attempts:
        since = len(fmu.log)
        c = fmu.lib.fmi2Instantiate(arg(name, b"raw"), 1, arg(guid, fmu.md.guid.encode()), arg(uri, fmu.uri()),
                                    byref(fmu._callbacks), 0, 0)
        result = {"null": c is None, "log": fmu.messages(since)}
        if c is not None:
            fmu.init(c)
            result["outputs"] = fmu.step(c, 0)
            result["terminate"] = fmu.lib.fmi2Terminate(c)
            fmu.lib.fmi2FreeInstance(c)
        results[label] = result
    results["null callbacks"] = {"null": fmu.instantiate(callbacks=False) is None}
    return results


def case_debug_logging(fmu, _args):
    c = fmu.instantiate()
    calls = {
        "[NULL]": (1, [None]),
        "[logAll, NULL]": (2, [b"logAll", None]),
        "non-UTF-8": (1, [b"log\xffAll"]),
        "unknown category": (1, [b"logEverything"]),
        "categories NULL": (2, None),
        "declared categories": (2, [b"logStatusError", b"logAll"]),
        "none": (0, None),
    }
    results = {}
    for label, (n, cats) in calls.items():
        since = len(fmu.log)
        array = None if cats is None else (c_char_p * len(cats))(*cats)
        results[label] = {"status": fmu.lib.fmi2SetDebugLogging(c, 1, n, array), "log": fmu.messages(since)}
    fmu.init(c)
    results["still usable"] = fmu.step(c, 0)
    fmu.lib.fmi2FreeInstance(c)
    return results


def case_strings(fmu, _args):
    c = fmu.instantiate()
    vr = (c_uint * 1)(fmu.vr["Kp_x"])
    results = {}
    for label, value in {"NULL": None, "non-UTF-8": b"\xc3\x28", "text": b"0.2"}.items():
        since = len(fmu.log)
        status = fmu.lib.fmi2SetString(c, vr, 1, (c_char_p * 1)(value))
        results[label] = {"status": status, "log": fmu.messages(since)}
    results["NULL vr"] = fmu.lib.fmi2SetReal(c, None, 1, (c_double * 1)(0.2))
    results["NULL values"] = fmu.lib.fmi2SetReal(c, vr, 1, None)
    fmu.init(c)
    results["still usable"] = fmu.step(c, 0)
    fmu.lib.fmi2FreeInstance(c)
    return results


def _learned(fmu, params, steps=120):
    """An initialized instance that has learned for `steps` steps, and its serialized state."""
    c = fmu.init(fmu.instantiate(), **params)
    for k in range(steps):
        fmu.step(c, k)
    return c, fmu.serialize(c)


def case_bitflip(fmu, args):
    """Flip bits of a real serialized state (every bit, or `count` random ones from `seed`):
    deserialize must answer fmi2Error every time; afterwards the instance is unchanged and
    goes on exactly like a twin that never saw a corrupt blob."""
    c, blob = _learned(fmu, {"n_neurons": args["n_neurons"]})
    twin, _ = _learned(fmu, {"n_neurons": args["n_neurons"]})
    bits = range(8 * len(blob))
    if args.get("count"):
        bits = random.Random(args["seed"]).sample(bits, args["count"])
    counts = {}
    for bit in bits:
        corrupt = bytearray(blob)
        corrupt[bit // 8] ^= 1 << (bit % 8)
        del fmu.log[:]  # keep memory flat over tens of thousands of refusals
        status, state = fmu.deserialize(c, bytes(corrupt))
        counts[status] = counts.get(status, 0) + 1
        if status == OK:  # must not happen; do not leak it
            fmu.lib.fmi2FreeFMUstate(c, byref(state))
    unchanged = fmu.serialize(c) == blob
    same_future = [fmu.step(c, k) for k in range(120, 130)] == [fmu.step(twin, k) for k in range(120, 130)]
    restored = fmu.restore(c, blob)
    for inst in (c, twin):
        fmu.lib.fmi2FreeInstance(inst)
    return {"flips": len(bits), "blob_bytes": len(blob), "statuses": {str(k): v for k, v in counts.items()},
            "unchanged": unchanged, "same_future": same_future, "restore_original": restored}


def case_crafted_states(fmu, _args):
    """Blobs with one precise defect each (checksum resealed where the defect is behind it)."""
    c, blob = _learned(fmu, {"n_neurons": 20})
    text_at = blob.index(b'"Kp_x": 0.1')
    kp_flip = bytearray(blob)
    kp_flip[text_at + len('"Kp_x": 0.')] ^= 0x02  # 0.1 -> 0.3: the JSON stays valid
    other_guid = bytearray(blob)
    other_guid[GUID_OFFSET + 1:GUID_OFFSET + 9] = b"00000000"
    cases = {
        "Kp_x 0.1 -> 0.3 in the JSON": bytes(kp_flip),
        "Kp_x 0.1 -> 0.3, checksum resealed": reseal(bytes(kp_flip)),
        "time NaN": reseal(blob[:TIME_OFFSET] + struct.pack("<d", math.nan) + blob[TIME_OFFSET + 8:]),
        "time +inf": reseal(blob[:TIME_OFFSET] + struct.pack("<d", math.inf) + blob[TIME_OFFSET + 8:]),
        "time -inf": reseal(blob[:TIME_OFFSET] + struct.pack("<d", -math.inf) + blob[TIME_OFFSET + 8:]),
        "another FMU's GUID": reseal(bytes(other_guid)),
        "format version 1": reseal(blob[:4] + struct.pack("<I", 1) + blob[8:]),
        "truncated by one byte": blob[:-1],
        "truncated to the header": blob[:64],
        "empty": b"",
        "one byte appended": blob + b"\0",
        "zeros": bytes(len(blob)),
        "forged: Kp_x = 99": forge(blob, lambda j: j["values"].update(Kp_x=99.0)),
        "forged: Kp_x = NaN": forge(blob, lambda j: j["values"].update(Kp_x=math.nan)),
        "forged: vx is text": forge(blob, lambda j: j["values"].update(vx="fast")),
        "forged: no vx": forge(blob, lambda j: j["values"].__delitem__("vx")),
        "forged: unknown phase": forge(blob, lambda j: j.update(phase="running")),
        "forged: JSON time inf": forge(blob, lambda j: j.update(time_s=math.inf)),
        "forged: JSON n_neurons 10, core 20": forge(blob, lambda j: j["values"].update(n_neurons=10)),
        "forged: core truncated": forge(blob, edit_core=lambda c: c[:-8]),
        "forged: JSON a list": forge(blob, json_value=[1, 2]),
    }
    results = {}
    for label, bad in cases.items():
        since = len(fmu.log)
        status, state = fmu.deserialize(c, bad)
        if status == OK:
            status = [status, fmu.lib.fmi2SetFMUstate(c, state)]
            fmu.lib.fmi2FreeFMUstate(c, byref(state))
        results[label] = {"status": status, "log": fmu.messages(since)}
    results["unchanged"] = fmu.serialize(c) == blob
    results["steps after"] = [fmu.lib.fmi2DoStep(c, (120 + k) * H, H, 1) for k in range(3)]
    fmu.lib.fmi2FreeInstance(c)
    return results


PHASE_OFFSET = 16  # u32 FMI phase in the guard's serialized state (guard_state.c)


def _header_patched(blob: bytes, offset: int, fmt: str, value) -> bytes:
    """``blob`` with one header field changed and the CRC-64 resealed."""
    body = bytearray(blob)
    struct.pack_into(fmt, body, offset, value)
    return reseal(bytes(body))


def _duplicate_time(scalars_text: bytes) -> bytes:
    """The slave's JSON with a second "time_s" key at its end: json.loads keeps the last one, the
    guard reads the first (which agrees with its header)."""
    return scalars_text[:-1] + b', "time_s": 9.0}'


def case_forged_agreement(fmu, _args):
    """Sealed states (every checksum right) whose guard header and slave blob disagree on the
    phase or the time, or whose slave JSON repeats a key: each must answer fmi2Error at
    deserialization, the instance unchanged and still able to go on.  Uses no variable, so it
    runs on the regulator and on the plant FMU alike."""
    fresh = fmu.instantiate(b"fresh")
    instantiated = fmu.serialize(fresh)
    c = fmu.init(fmu.instantiate(b"stepping"))
    assert fmu.lib.fmi2DoStep(c, 0.0, H, 1) == OK, fmu.log[-3:]
    stepped = fmu.serialize(c)

    def duplicate_key(blob):
        head, slave = split_state(blob)
        _, version, n_text, n_core = struct.unpack_from("<4sIII", slave)
        text = _duplicate_time(slave[16:16 + n_text])
        body = struct.pack("<4sIII", b"AVRS", version, len(text), n_core) + text + slave[16 + n_text:16 + n_text + n_core]
        slave = body + struct.pack("<I", zlib.crc32(body))
        out = head[:-8] + struct.pack("<Q", len(slave)) + slave
        return out + struct.pack("<Q", crc64(out))

    cases = {
        "header initializationMode, slave instantiated": _header_patched(instantiated, PHASE_OFFSET, "<I", 1),
        "header stepComplete, slave instantiated": _header_patched(instantiated, PHASE_OFFSET, "<I", 2),
        "header instantiated, slave stepComplete": _header_patched(stepped, PHASE_OFFSET, "<I", 0),
        "header time 5 s, slave 0.005 s": _header_patched(stepped, TIME_OFFSET, "<d", 5.0),
        "header time 0.005 s, slave 7 s": forge(stepped, lambda j: j.update(time_s=7.0)),
        "slave JSON repeats time_s": duplicate_key(stepped),
    }
    results = {}
    for label, bad in cases.items():
        since = len(fmu.log)
        status, state = fmu.deserialize(c, bad)
        if status == OK:
            status = [status, fmu.lib.fmi2SetFMUstate(c, state), fmu.lib.fmi2DoStep(c, H, H, 1)]
            fmu.lib.fmi2FreeFMUstate(c, byref(state))
        results[label] = {"status": status, "log": fmu.messages(since)}
    results["unchanged"] = fmu.serialize(c) == stepped
    results["own states restore"] = [fmu.restore(fresh, instantiated), fmu.restore(c, stepped)]
    results["steps after"] = [fmu.lib.fmi2DoStep(c, (1 + k) * H, H, 1) for k in range(2)]
    for inst in (fresh, c):
        fmu.lib.fmi2FreeInstance(inst)
    return results


def _walker_edit(edit):
    """An edit_core for forge(): the CassiePlant walker state (fmu_src/plant_fmu/fmu_core.py: "CPWS", u32 version,
    u32 JSON length, JSON) with ``edit`` applied to its JSON."""
    def apply(core: bytes) -> bytes:
        magic, version, n = struct.unpack_from("<4sII", core)
        state = json.loads(core[12:12 + n])
        edit(state)
        text = json.dumps(state, sort_keys=True).encode()
        return struct.pack("<4sII", magic, version, len(text)) + text
    return apply


def _set_item(key, index, value):
    return lambda state: state[key].__setitem__(index, value)


#: The plant's forged walker states: (what is forged, the edit of the walker state's JSON).
WALKER_FORGERIES = {
    "walker vx_des = NaN": lambda s: s["walker"].update(vx_des=math.nan),
    "controller mode = 'garbage'": lambda s: s["controller"].update(mode="garbage"),
    "controller stance = 'up'": lambda s: s["controller"].update(stance="up"),
    "controller offsets NaN": lambda s: s["controller"]["offsets"].update(delta_swing_knee=math.nan),
    "pelvis quaternion zero": lambda s: s["physics"].__setitem__(slice(4, 8), [0.0] * 4),  # time, x, y, z, quat
    "pelvis z = 1e300": _set_item("physics", 3, 1e300),
    "commanded vx 5 m/s (input range [-3, 3])": lambda s: s["controller"].update(vx_des=5.0),
    "controller step times after the physics time": lambda s: s["controller"].update(_last_t=1e6),
}


def case_forged_walker(fmu, _args):
    """The CassiePlant FMU: sealed states whose walker memory no run can reach.  Each must be
    refused with fmi2Error (at deserialization or at fmi2SetFMUstate, never OK then, never
    Fatal), the instance unchanged and still stepping."""
    c = fmu.init(fmu.instantiate(b"plant"))
    for k in range(4):
        assert fmu.lib.fmi2DoStep(c, k * H, H, 1) == OK, fmu.log[-3:]
    blob = fmu.serialize(c)
    results = {}
    for label, edit in WALKER_FORGERIES.items():
        since = len(fmu.log)
        status, state = fmu.deserialize(c, forge(blob, edit_core=_walker_edit(edit)))
        if status == OK:
            status = [status, fmu.lib.fmi2SetFMUstate(c, state)]
            fmu.lib.fmi2FreeFMUstate(c, byref(state))
            if status[1] == OK:
                status.append(fmu.lib.fmi2DoStep(c, 4 * H, H, 1))
        results[label] = {"status": status, "log": fmu.messages(since)}
    results["unchanged"] = fmu.serialize(c) == blob
    results["steps after"] = [fmu.lib.fmi2DoStep(c, (4 + k) * H, H, 1) for k in range(2)]
    fmu.lib.fmi2FreeInstance(c)
    return results


def case_step_bound(fmu, args):
    """Communication steps beyond the FMU's maximum (args["max_step"], s) right after
    initialization: each must answer fmi2Error at once (wall time recorded), leave the instance
    where it was (the next step from the same time is accepted), and a step of exactly the
    maximum must be done."""
    import time

    c = fmu.init(fmu.instantiate(b"bound"))
    results = {}
    for label, h in (("1e9 s", 1e9), ("1e300 s", 1e300), ("just over the maximum", args["max_step"] + H)):
        since, start = len(fmu.log), time.perf_counter()
        results[label] = {"status": fmu.lib.fmi2DoStep(c, 0.0, h, 1), "wall_s": time.perf_counter() - start,
                          "log": fmu.messages(since)}
    results["then a 5 ms step"] = fmu.lib.fmi2DoStep(c, 0.0, H, 1)
    start = time.perf_counter()
    results["then the maximum"] = fmu.lib.fmi2DoStep(c, H, args["max_step"], 1)
    results["maximum_wall_s"] = time.perf_counter() - start
    fmu.lib.fmi2FreeInstance(c)
    return results


def case_foreign_state(fmu, _args):
    """A state from an instance with other fixed parameters is refused until they match."""
    a, blob = _learned(fmu, {"n_neurons": 20, "seed": 0})
    a_state = fmu.get_state(a)
    results = {}
    b = fmu.instantiate(b"b")
    assert fmu.set(b, "n_neurons", 10) == OK and fmu.set(b, "seed", 5) == OK
    since = len(fmu.log)
    results["into instantiated n_neurons=10 seed=5"] = {"status": fmu.restore(b, blob), "log": fmu.messages(since)}
    since = len(fmu.log)
    results["in-memory state into b"] = {"status": fmu.lib.fmi2SetFMUstate(b, a_state), "log": fmu.messages(since)}
    fmu.init(b)
    since = len(fmu.log)
    results["into initialized n_neurons=10 seed=5"] = {"status": fmu.restore(b, blob), "log": fmu.messages(since)}
    results["b still steps"] = fmu.lib.fmi2DoStep(b, 0.0, H, 1)
    c = fmu.instantiate(b"c")
    assert fmu.set(c, "n_neurons", 20) == OK and fmu.set(c, "seed", 0) == OK
    results["into matching instance"] = fmu.restore(c, blob)
    results["continues like the original"] = [fmu.step(c, k) for k in range(120, 125)] == [
        fmu.step(a, k) for k in range(120, 125)]
    fmu.lib.fmi2FreeFMUstate(a, byref(a_state))
    for inst in (a, b, c):
        fmu.lib.fmi2FreeInstance(inst)
    return results


def case_fatal_cycles(fmu, args):
    """FMU_DIR's slave raises in exit_initialization_mode (a test copy): pythonfmu answers Fatal.
    Every later call must be refused without reaching pythonfmu, and fmi2FreeInstance must be
    safe, cycle after cycle (pythonfmu would free the slave's Python objects twice)."""
    results = []
    for _ in range(args["cycles"]):
        c = fmu.instantiate()
        before = fmu.get_state(c)
        statuses = {"exit": (fmu.lib.fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0),
                             fmu.lib.fmi2EnterInitializationMode(c), fmu.lib.fmi2ExitInitializationMode(c))}
        statuses["doStep"] = fmu.lib.fmi2DoStep(c, 0.0, H, 1)
        statuses["set"] = fmu.set(c, "vx", 0.1)
        statuses["reset"] = fmu.lib.fmi2Reset(c)
        statuses["free state"] = fmu.lib.fmi2FreeFMUstate(c, byref(before))
        fmu.lib.fmi2FreeInstance(c)
        gc.collect()
        results.append(statuses)
    return {"cycles": results, "log": fmu.messages()}


def main():
    fmu = RawFmu(sys.argv[1])
    args = json.loads(sys.stdin.read() or "null")
    print(json.dumps(globals()[f"case_{sys.argv[2]}"](fmu, args)), flush=True)


if __name__ == "__main__":
    main()
