"""The dynamic checks: the FMU's binary called through :class:`~.capi.Binary`.  They run in the
conformance child process (``child.py``); each raises :class:`Failed` naming the call that broke
the rule, or :class:`Skipped` with the reason, or returns what it measured."""
from __future__ import annotations

import ctypes
import gc
import math
import os
import random
import struct
from ctypes import byref, c_uint32, c_void_p

from fmu_src.fmi import phase_rules
from fmu_src.fmi.conformance.capi import DISCARD, ERROR, FATAL, OK, STATE_FUNCTIONS, STATUS_NAMES, WARNING, Binary
from fmu_src.fmi.conformance.model import Fmu

ACCEPTED = (OK, WARNING)
#: The path from instantiation to each state, and the states' names per version (phase_rules).
ROUTES = {2: {"instantiated": (), "initializationMode": ("enter",), "stepComplete": ("enter", "exit"),
              "terminated": ("enter", "exit", "terminate")},
          3: {"Instantiated": (), "InitializationMode": ("enter",), "StepMode": ("enter", "exit"),
              "Terminated": ("enter", "exit", "terminate")}}
ALLOWED = {2: phase_rules.FMI2_ALLOWED, 3: phase_rules.FMI3_ALLOWED}
#: Calls that change the state when allowed: each gets an instance of its own.
MOVERS = {f"fmi{v}{f}" for v in (2, 3) for f in ("EnterInitializationMode", "ExitInitializationMode", "Terminate",
                                                 "Reset", "DoStep", "EnterConfigurationMode",
                                                 "ExitConfigurationMode", "EnterEventMode", "EnterStepMode")}


class Failed(Exception):
    """A rule broken: the message names the call and its arguments."""


class Skipped(Exception):
    """The check does not apply to this FMU (the reason)."""


def status_name(status) -> str:
    return STATUS_NAMES[status] if isinstance(status, int) and 0 <= status < len(STATUS_NAMES) else repr(status)


class Context:
    """The FMU, its binary, the options, and the helpers every check shares."""

    def __init__(self, fmu: Fmu, binary: Binary, options: dict):
        self.fmu, self.api, self.options = fmu, binary, options
        self.h = options.get("step") or fmu.step_size
        self.steps = options["steps"]
        self.last_call = ""
        self.version = fmu.version
        self.states = ROUTES[fmu.version]
        exchangeable = [v for v in fmu.variables if v.scalar and binary.value_type(v.type) is not None]
        self.inputs = [v for v in exchangeable if v.causality == "input" and v.start is not None]
        self.outputs = [v for v in exchangeable if v.causality == "output"]

    # ---- rules ---------------------------------------------------------------------------------
    def expect(self, status, allowed, what=""):
        """``status`` must be one of ``allowed``; otherwise Failed naming the last call."""
        if status not in allowed:
            wanted = " or ".join(status_name(s) for s in allowed)
            log = self.api.log[-1:] if self.api.log else []
            raise Failed(f"{self.last_call} returned {status_name(status)}, expected {wanted}"
                         + (f" ({what})" if what else "") + (f"; last log message: {log[0]!r}" if log else ""))

    # ---- instances -----------------------------------------------------------------------------
    def instance(self, state=None, **kwargs):
        """A new instance, brought to ``state`` (default: the step state)."""
        inst = self.api.instantiate(**kwargs)
        if not inst:
            raise Failed(f"{self.last_call} returned NULL for valid arguments")
        route = self.states[state or list(self.states)[2]]
        for move in route:
            statuses = {"enter": lambda: self.api.enter_init(inst), "exit": lambda: [self.api.exit_init(inst)],
                        "terminate": lambda: [self.api.terminate(inst)]}[move]()
            for status in statuses:
                self.expect(status, ACCEPTED, "on the way to a state")
        return inst

    def input_values(self, k: int, seed: int) -> dict:
        """Inputs for step ``k``: each input's start moved by a seeded draw of at most 5 % of its
        range (inputs without a finite range, and non-float inputs, stay at their start)."""
        rng = random.Random(seed * 1_000_003 + k)
        values = {}
        for v in self.inputs:
            value = v.valid_value()
            if v.type in ("Real", "Float64", "Float32") and v.min is not None and v.max is not None \
                    and math.isfinite(v.max - v.min):
                value = min(v.max, max(v.min, value + 0.05 * (v.max - v.min) * (2 * rng.random() - 1)))
            values[v] = value
        return values

    def set_inputs(self, inst, k, seed):
        by_type = {}
        for v, value in self.input_values(k, seed).items():
            by_type.setdefault(v.type, ([], []))
            by_type[v.type][0].append(v.vr)
            by_type[v.type][1].append(value)
        for var_type, (vrs, values) in by_type.items():
            self.expect(self.api.set(inst, var_type, vrs, values), ACCEPTED, "setting inputs within their ranges")

    def outputs_now(self, inst) -> list:
        values = []
        by_type = {}
        for v in self.outputs:
            by_type.setdefault(v.type, []).append(v.vr)
        for var_type, vrs in by_type.items():
            status, got = self.api.get(inst, var_type, vrs)
            self.expect(status, ACCEPTED, "getting the outputs")
            values += [bits(x) for x in got]
        return values

    def run(self, inst, first: int, n: int, seed: int) -> list:
        """Steps ``first`` .. ``first + n - 1`` with seeded inputs; the outputs after each (as bits)."""
        trace = []
        for k in range(first, first + n):
            self.set_inputs(inst, k, seed)
            self.expect(self.api.step(inst, k * self.h, self.h), ACCEPTED, f"step {k} with valid inputs")
            trace.append(self.outputs_now(inst))
        return trace

    def settable(self, state: str) -> list:
        """The variables one may set in ``state`` (FMI 2.0 section 4.2.4, FMI 3.0 state machine)."""
        instantiated, init = list(self.states)[:2]
        out = []
        for v in self.fmu.variables:
            if not v.scalar or v.start is None or self.api.value_type(v.type) is None:
                continue
            if v.causality not in ("parameter", "structuralParameter", "input"):
                continue  # outputs and locals with initial exact/approx: see docs/conformance.md
            if state in (instantiated, init):
                ok = v.variability != "constant" and (v.initial in ("exact", "approx") or v.causality == "input")
                if state == init and self.version == 2:
                    ok = v.variability != "constant" and (v.initial == "exact" or v.causality == "input")
            else:
                ok = v.causality == "input" or (v.causality == "parameter" and v.variability == "tunable")
            if ok:
                out.append(v)
        return out


def bits(x):
    """A value compared bit for bit (floats by their IEEE bytes, so NaN equals NaN and -0 != 0)."""
    return struct.pack("<d", x).hex() if isinstance(x, float) else x


def _group(variables):
    by_type = {}
    for v in variables:
        by_type.setdefault(v.type, []).append(v)
    return by_type


# ---- the state machine --------------------------------------------------------------------------
def legal_calls(ctx: Context):
    """In each state, each function the state allows with valid arguments; movers on an instance of their own."""
    api, v = ctx.api, ctx.version
    can_state, can_serialize = ctx.fmu.flag("canGetAndSetFMUstate"), ctx.fmu.flag("canSerializeFMUstate")
    readable = [x for x in ctx.fmu.variables if x.scalar and api.value_type(x.type) is not None
                and x.causality != "independent"]
    called = 0
    for state in ctx.states:
        allowed = {f for f, states in ALLOWED[v].items() if state in states and api.has(f)}
        inst = ctx.instance(state)
        if f"fmi{v}SetDebugLogging" in allowed:
            ctx.expect(api.call(f"fmi{v}SetDebugLogging", inst, 0, 0, None), ACCEPTED, f"in {state}")
            called += 1
        for var_type, group in _group(readable).items():
            if f"fmi{v}Get{api.accessor(var_type)}" in allowed:
                ctx.expect(api.get(inst, var_type, [x.vr for x in group])[0], ACCEPTED, f"in {state}")
                called += 1
        for var_type, group in _group(ctx.settable(state)).items():
            if f"fmi{v}Set{api.accessor(var_type)}" in allowed:
                ctx.expect(api.set(inst, var_type, [x.vr for x in group], [x.valid_value() for x in group]),
                           ACCEPTED, f"in {state}, start values")
                called += 1
        if can_state and STATE_FUNCTIONS[v]["get"] in allowed:
            status, saved = api.get_state(inst)
            ctx.expect(status, ACCEPTED, f"in {state}")
            if can_serialize:
                status, blob = api.serialize(inst, saved)
                ctx.expect(status, ACCEPTED, f"in {state}")
                status, copy = api.deserialize(inst, blob)
                ctx.expect(status, ACCEPTED, f"in {state}, its own serialized state")
                ctx.expect(api.free_state(inst, copy), ACCEPTED, f"in {state}")
            ctx.expect(api.set_state(inst, saved), ACCEPTED, f"in {state}, the state just saved")
            ctx.expect(api.free_state(inst, saved), ACCEPTED, f"in {state}")
            called += 4 + 3 * can_serialize
        api.free(inst)
        movers = {f"fmi{v}DoStep": lambda i: api.step(i, 0.0, ctx.h), f"fmi{v}Terminate": api.terminate,
                  f"fmi{v}Reset": api.reset, f"fmi{v}ExitInitializationMode": api.exit_init,
                  f"fmi{v}EnterInitializationMode": lambda i: api.enter_init(i)[-1]}
        for name, move in movers.items():
            if name in allowed:
                inst = ctx.instance(state)
                ctx.expect(move(inst), ACCEPTED, f"in {state}")
                api.free(inst)
                called += 1
    return {"calls": called}


def illegal_calls(ctx: Context):
    """In each state, each function the state does not allow, every argument zero or NULL: Error."""
    api, v = ctx.api, ctx.version
    wrong = []
    called = 0
    for state in ctx.states:
        shared = ctx.instance(state)
        for name in sorted(ALLOWED[v]):
            if state in ALLOWED[v][name] or not api.has(name):
                continue
            own = ctx.instance(state) if name in MOVERS else None
            status = api.zero_call(own or shared, name)
            called += 1
            if status != ERROR:
                wrong.append(f"{ctx.last_call} in {state} returned {status_name(status)}")
            if own:
                api.free(own)
        api.free(shared)
    if wrong:
        raise Failed(f"{len(wrong)} of {called} illegal calls not refused with Error: " + "; ".join(wrong[:5])
                     + ("; ..." if len(wrong) > 5 else ""))
    return {"calls": called}


def error_state(ctx: Context):
    """An illegal call (initialization in the step state) answers Error.  In the error state the
    standard allows getting values, restoring an FMU state saved before and fmiReset: the
    restored state must go on like an instance that never saw the Error, and after fmiReset a
    new initialization and run must give the outputs of a new instance."""
    api, n, seed = ctx.api, ctx.steps, ctx.options["seed"]
    can_state = ctx.fmu.flag("canGetAndSetFMUstate")
    fresh = ctx.instance()
    expected = ctx.run(fresh, 0, n, seed)
    api.free(fresh)
    inst = ctx.instance()
    first = ctx.run(inst, 0, 2, seed)
    if can_state:
        status, saved = api.get_state(inst)
        ctx.expect(status, ACCEPTED, "before the illegal call")
    ctx.expect(api.enter_init(inst)[-1], (ERROR,), "initialization is illegal in the step state")
    for var_type, group in _group(ctx.outputs).items():  # allowed in the error state (for debugging)
        api.get(inst, var_type, [x.vr for x in group])
    if can_state:
        ctx.expect(api.set_state(inst, saved), ACCEPTED, "restoring a state saved before the Error")
        if first + ctx.run(inst, 2, n - 2, seed) != expected:
            raise Failed("after an Error, the state restored does not go on like an instance that saw no Error")
        api.free_state(inst, saved)
    _reset_then_run_as_new(ctx, inst, expected, "after an Error")
    return {"restored": can_state}


def _reset_then_run_as_new(ctx: Context, inst, expected, after: str):
    """fmiReset ``inst`` (in the state ``after`` names), initialize it again and run it:
    its outputs must be ``expected``, a new instance's; then free it."""
    api = ctx.api
    ctx.expect(api.reset(inst), (OK,), f"fmiReset {after}")
    for status in api.enter_init(inst) + [api.exit_init(inst)]:
        ctx.expect(status, ACCEPTED, "initializing after the reset")
    if ctx.run(inst, 0, ctx.steps, ctx.options["seed"]) != expected:
        raise Failed(f"{after} and fmiReset the run's outputs differ from a new instance's")
    api.free(inst)


# ---- arguments ----------------------------------------------------------------------------------
def instantiate_arguments(ctx: Context):
    api = ctx.api
    token = api.token.encode()
    cases = {"another GUID/token": b"{00000000-0000-0000-0000-000000000000}", "empty GUID/token": b"",
             "NULL GUID/token": None, "GUID/token with one character changed": token[:-2] + bytes([token[-2] ^ 1])
             + token[-1:]}
    for label, bad in cases.items():
        inst = api.instantiate(token=bad) if bad is not None else _instantiate_null_token(api)
        if inst:
            call = ctx.last_call
            api.free(inst)
            raise Failed(f"{call} ({label}) returned an instance, expected NULL")
    if ctx.version == 2:
        inst = api.handle(api.call("fmi2Instantiate", b"conformance", 0, token, api.resources.as_uri().encode(),
                                   api_callbacks(api), 0, 0, restype=c_void_p))
        if inst and ctx.fmu.root.find("ModelExchange") is None:
            call = ctx.last_call
            api.free(inst)
            raise Failed(f"{call} (fmuType fmi2ModelExchange, the FMU has no ModelExchange) returned an "
                         "instance, expected NULL")
        if inst:
            api.free(inst)
    inst = ctx.instance()  # valid arguments still work
    ctx.run(inst, 0, 1, ctx.options["seed"])
    api.free(inst)
    return {"cases": len(cases) + (ctx.version == 2)}


def api_callbacks(api):
    return byref(api.callbacks)


def _instantiate_null_token(api):
    if api.version == 2:
        return api.handle(api.call("fmi2Instantiate", b"conformance", 1, None, api.resources.as_uri().encode(),
                                   api_callbacks(api), 0, 0, restype=c_void_p))
    return api.handle(api.call("fmi3InstantiateCoSimulation", b"conformance", None,
                               (str(api.resources) + "/").encode(), False, False, False, False, None, 0, None, None,
                               None, restype=c_void_p))


def null_callbacks(ctx: Context):
    """FMI 2.0: ``functions`` NULL may be refused (NULL) but must not crash; FMI 3.0: a NULL
    logMessage is allowed, so the instance must work, also when it has something to log."""
    api = ctx.api
    inst = api.instantiate(callbacks=False) if ctx.version == 2 else api.instantiate(logger=False)
    if not inst:
        if ctx.version == 3:
            raise Failed(f"{ctx.last_call} (logMessage NULL, which the standard allows) returned NULL")
        return {"instance": "refused (NULL)"}
    for status in api.enter_init(inst):
        ctx.expect(status, ACCEPTED, "NULL callbacks")
    ctx.expect(api.exit_init(inst), ACCEPTED, "NULL callbacks")
    ctx.expect(api.enter_init(inst)[-1], (ERROR,), "an illegal call, which the FMU would log")
    ctx.expect(api.step(inst, 0.0, ctx.h), ACCEPTED, "NULL callbacks")
    api.free(inst)
    return {"instance": "created and used"}


def null_arrays(ctx: Context):
    api, v = ctx.api, ctx.version
    inst = ctx.instance()
    cases = 0
    for var_type in sorted({x.type for x in ctx.outputs} | {x.type for x in ctx.inputs}):
        accessor = api.accessor(var_type)
        tail = (1,) if v == 3 else ()
        values = (api.value_type(var_type) * 1)()
        refs = (c_uint32 * 1)((ctx.outputs or ctx.inputs)[0].vr)
        for args in ((None, 1, values), (refs, 1, None)):
            ctx.expect(api.call(f"fmi{v}Get{accessor}", inst, *args, *tail), (ERROR,), "NULL array with nvr = 1")
            cases += 1
        if ctx.inputs:
            refs = (c_uint32 * 1)(ctx.inputs[0].vr)
            ctx.expect(api.call(f"fmi{v}Set{accessor}", inst, refs, 1, None, *tail), (ERROR,),
                       "NULL values with nvr = 1")
            cases += 1
    if ctx.fmu.flag("canGetAndSetFMUstate"):
        ctx.expect(api.set_state(inst, None), (ERROR,), "a NULL FMU state")
        ctx.expect(api.state_call("get", inst, None), (ERROR,), "a NULL pointer for the FMU state")
        cases += 2
    ctx.run(inst, 0, 1, ctx.options["seed"])
    api.free(inst)
    return {"cases": cases}


def unknown_vr(ctx: Context):
    api = ctx.api
    inst = ctx.instance()
    known = {x.vr for x in ctx.fmu.variables}
    unknown = [max(known) + 1, 0xFFFFFFFF] if known else [0, 0xFFFFFFFF]
    unknown = [u for u in unknown if u not in known]
    types = sorted({x.type for x in ctx.outputs} | {x.type for x in ctx.inputs})
    for var_type in types:
        for vr in unknown:
            ctx.expect(api.get(inst, var_type, [vr])[0], (ERROR,), "a value reference no variable has")
            if var_type != "String":
                ctx.expect(api.set(inst, var_type, [vr], [0]), (ERROR,), "a value reference no variable has")
    ctx.run(inst, 0, 1, ctx.options["seed"])
    api.free(inst)
    return {"value_references": unknown, "types": types}


def _outside(v):
    """Values just outside ``v``'s [min, max]: one ulp (floats) or one (integers) beyond, and NaN."""
    values = []
    for bound, direction in ((v.max, math.inf), (v.min, -math.inf)):
        if bound is None or not math.isfinite(bound):
            continue
        if v.type in ("Real", "Float64"):
            values.append(math.nextafter(bound, direction))
        elif v.type == "Float32":
            values.append(bound + (abs(bound) + 1) * 1e-6 * (1 if direction > 0 else -1))
        else:
            values.append(int(bound) + (1 if direction > 0 else -1))
    if values and v.type in ("Real", "Float64", "Float32"):
        values.append(math.nan)
    return values


def _fits(v, value, ctype):
    try:
        return ctype(value).value == value or (isinstance(value, float) and math.isnan(value))
    except (TypeError, OverflowError):
        return False


def out_of_range(ctx: Context):
    """Values just outside [min, max]: the standard lets the FMU refuse them (Discard, Error) or
    handle them; it must never crash or answer Fatal, and after a refusal the instance goes on."""
    api = ctx.api
    counts = {"refused": 0, "accepted": 0}
    instantiated, _, step_state = list(ctx.states)[:3]
    for state in (instantiated, step_state):
        inst = ctx.instance(state)
        for v in ctx.settable(state):
            if v.type in ("String", "Boolean") or not v.bounded():
                continue
            for value in _outside(v):
                if not _fits(v, value, api.value_type(v.type)):
                    continue
                status = api.set(inst, v.type, [v.vr], [value])
                if status == FATAL or status not in (OK, WARNING, DISCARD, ERROR):
                    raise Failed(f"{ctx.last_call} in {state} returned {status_name(status)} for a value outside "
                                 "[min, max]")
                counts["accepted" if status in ACCEPTED else "refused"] += 1
                ctx.expect(api.set(inst, v.type, [v.vr], [v.valid_value()]), ACCEPTED,
                           "the start value again after a value outside [min, max]")
        if state == step_state:
            ctx.run(inst, 0, 1, ctx.options["seed"])
        api.free(inst)
    if not sum(counts.values()):
        raise Skipped("no settable variable has a finite min or max")
    return counts


def step_size(ctx: Context):
    api = ctx.api
    inst = ctx.instance()
    t = 0.0
    statuses = {}
    for label, h in (("negative", -ctx.h), ("zero", 0.0), ("NaN", math.nan), ("+inf", math.inf),
                     ("huge 1e300", 1e300)):
        status = api.step(inst, t, h)
        statuses[label] = status_name(status)
        if status == FATAL:
            raise Failed(f"{ctx.last_call} ({label} step) returned Fatal")
        if label in ("negative", "NaN", "+inf") and status in ACCEPTED:
            raise Failed(f"{ctx.last_call} ({label} step) returned {status_name(status)}, expected a refusal")
        if status in ACCEPTED:
            t += h
        if label != "huge 1e300" or status not in ACCEPTED:
            ctx.expect(api.step(inst, t, ctx.h), ACCEPTED, f"a valid step after the {label} one")
            t += ctx.h
    api.free(inst)
    return {"statuses": statuses}


# ---- FMU state ------------------------------------------------------------------------------------
def _need(ctx, flag):
    if not ctx.fmu.flag(flag):
        raise Skipped(f"{flag if ctx.version == 2 else flag.replace('FMUstate', 'FMUState')} is false")


def _saved_run(ctx):
    """An instance after ``steps`` steps, its FMU state there and the outputs of the next ``steps``."""
    api, n, seed = ctx.api, ctx.steps, ctx.options["seed"]
    inst = ctx.instance()
    ctx.run(inst, 0, n, seed)
    status, state = api.get_state(inst)
    ctx.expect(status, ACCEPTED)
    return inst, state, ctx.run(inst, n, n, seed)


def restore(ctx: Context):
    _need(ctx, "canGetAndSetFMUstate")
    api, n = ctx.api, ctx.steps
    inst, state, expected = _saved_run(ctx)
    ctx.expect(api.set_state(inst, state), ACCEPTED, "restoring the state saved")
    if ctx.run(inst, n, n, ctx.options["seed"]) != expected:
        raise Failed(f"after restoring the saved FMU state the next {n} steps differ from the first time")
    api.free_state(inst, state)
    api.free(inst)
    return {"steps": n}


def serialize(ctx: Context):
    _need(ctx, "canSerializeFMUstate")
    api, n = ctx.api, ctx.steps
    inst, state, expected = _saved_run(ctx)
    status, blob = api.serialize(inst, state)
    ctx.expect(status, ACCEPTED)
    status, copy = api.deserialize(inst, blob)
    ctx.expect(status, ACCEPTED, "the FMU's own serialized state")
    status, again = api.serialize(inst, copy)
    ctx.expect(status, ACCEPTED)
    if again != blob:
        raise Failed(f"serialize -> deserialize -> serialize changed the bytes ({len(blob)} -> {len(again)} bytes)")
    ctx.expect(api.set_state(inst, copy), ACCEPTED, "the deserialized state")
    if ctx.run(inst, n, n, ctx.options["seed"]) != expected:
        raise Failed(f"the deserialized state's next {n} steps differ from the original's")
    for s in (state, copy):
        api.free_state(inst, s)
    api.free(inst)
    return {"bytes": len(blob)}


def tampered(ctx: Context):
    _need(ctx, "canSerializeFMUstate")
    api, n, seed = ctx.api, ctx.steps, ctx.options["seed"]
    inst, state, expected = _saved_run(ctx)
    status, blob = api.serialize(inst, state)
    ctx.expect(status, ACCEPTED)
    rng = random.Random(seed)
    cases = {}
    for bit in sorted(rng.sample(range(8 * len(blob)), min(ctx.options["flips"], 8 * len(blob)))):
        flipped = bytearray(blob)
        flipped[bit // 8] ^= 1 << (bit % 8)
        cases[f"bit {bit} flipped"] = bytes(flipped)
    cases.update({"truncated by one byte": blob[:-1], "truncated to half": blob[:len(blob) // 2], "empty": b"",
                  "one byte appended": blob + b"\0", "zeros": bytes(len(blob)),
                  "foreign: seeded random bytes": bytes(rng.getrandbits(8) for _ in range(len(blob)))})
    outcome = {"refused": 0, "accepted, equal to the untampered restore": 0}
    for label, bad in cases.items():
        status, copy = api.deserialize(inst, bad)
        if status == FATAL or status not in (OK, WARNING, DISCARD, ERROR):
            raise Failed(f"{ctx.last_call} ({label}) returned {status_name(status)}, expected Error")
        if status in ACCEPTED:
            status = api.set_state(inst, copy)
            api.free_state(inst, copy)
            if status in ACCEPTED:
                if ctx.run(inst, n, n, seed) != expected:
                    raise Failed(f"a serialized state with {label} was accepted and its next {n} steps differ "
                                 "from the untampered state's")
                outcome["accepted, equal to the untampered restore"] += 1
                continue
            if status == FATAL:
                raise Failed(f"{ctx.last_call} ({label}) returned Fatal")
        outcome["refused"] += 1
    ctx.expect(api.set_state(inst, state), ACCEPTED, "the genuine state after the tampered ones")
    if ctx.run(inst, n, n, seed) != expected:
        raise Failed("after the tampered states, the genuine one no longer gives its outputs")
    api.free_state(inst, state)
    api.free(inst)
    return {"cases": len(cases), "blob_bytes": len(blob), **outcome}


# ---- life cycle -----------------------------------------------------------------------------------
def _rss_kib() -> int:
    """Resident memory after a garbage collection and, with glibc, ``malloc_trim(0)`` (freed heap
    pages returned to the system, so that fragmentation is not counted as growth)."""
    gc.collect()
    try:
        ctypes.CDLL(None).malloc_trim(0)
    except AttributeError:  # not glibc
        pass
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") // 1024


def memory(ctx: Context):
    api, cycles = ctx.api, ctx.options["cycles"]
    warmup = cycles // 2  # the first cycles fill caches (the FMU's, the allocator's, an embedded Python's)
    rss = []
    for k in range(cycles):
        inst = ctx.instance()
        ctx.run(inst, 0, 1, ctx.options["seed"])
        ctx.expect(api.terminate(inst), ACCEPTED)
        api.free(inst)
        api.log.clear()  # the checker's own memory stays flat
        if k + 1 >= warmup:
            rss.append(_rss_kib())
    growth = rss[-1] - rss[0]
    per_cycle = growth / max(1, len(rss) - 1)
    details = {"cycles": cycles, "rss_kib_after_warmup": rss[0], "growth_kib": growth,
               "growth_kib_per_cycle": round(per_cycle, 1)}
    if per_cycle > ctx.options["max_growth_kib"]:
        raise Failed(f"resident memory grew {growth} KiB over {len(rss) - 1} instantiate/free cycles "
                     f"({per_cycle:.1f} KiB per cycle, bound {ctx.options['max_growth_kib']} KiB)")
    return details


def independence(ctx: Context):
    if ctx.fmu.flag("canBeInstantiatedOnlyOncePerProcess"):
        raise Skipped("canBeInstantiatedOnlyOncePerProcess is true")
    api, n, seed = ctx.api, ctx.steps, ctx.options["seed"]
    solo = ctx.instance()
    expected = ctx.run(solo, 0, n, seed)
    api.free(solo)
    a = ctx.instance(name=b"first")
    b = ctx.instance(name=b"second")
    got = []
    for k in range(n):
        got += ctx.run(a, k, 1, seed)
        ctx.run(b, k, 1, seed + 1)
    for inst in (a, b):
        api.free(inst)
    if got != expected:
        raise Failed("the first instance's outputs changed when a second one ran beside it with other inputs")
    return {"steps": n}


def reset(ctx: Context):
    api, n, seed = ctx.api, ctx.steps, ctx.options["seed"]
    fresh = ctx.instance()
    expected = ctx.run(fresh, 0, n, seed)
    api.free(fresh)
    inst = ctx.instance()
    ctx.run(inst, 0, n, seed + 1)
    _reset_then_run_as_new(ctx, inst, expected, "after a run")
    return {"steps": n}


def determinism(ctx: Context):
    api, n, seed = ctx.api, ctx.steps, ctx.options["seed"]
    runs = []
    for _ in range(2):
        inst = ctx.instance()
        runs.append(ctx.run(inst, 0, n, seed))
        api.free(inst)
    if runs[0] != runs[1]:
        first = next(k for k in range(n) if runs[0][k] != runs[1][k])
        raise Failed(f"two runs with the same inputs differ from step {first} on")
    return {"steps": n, "outputs": len(ctx.outputs)}


DYNAMIC_CHECKS = {
    "machine.legal_calls": legal_calls, "machine.illegal_calls": illegal_calls, "machine.error_state": error_state,
    "arguments.instantiate": instantiate_arguments, "arguments.null_callbacks": null_callbacks,
    "arguments.null_arrays": null_arrays, "arguments.unknown_vr": unknown_vr,
    "arguments.out_of_range": out_of_range, "arguments.step_size": step_size,
    "state.restore": restore, "state.serialize": serialize, "state.tampered": tampered,
    "lifecycle.memory": memory, "lifecycle.independence": independence, "lifecycle.reset": reset,
    "lifecycle.determinism": determinism,
}
