"""The command and push schedules are looked up in O(log n) per communication step, with
the semantics of the linear scan they replace (which value holds at step k, at the exact
switch steps, and the push sums added in the file's order)."""
from __future__ import annotations

import time

from hypothesis import given, settings, strategies as st

from scenarios.lang.scenario import Arm, CommandPoint, Push, Scenario, to_step

H = 0.005


def linear_command(s: Scenario, k: int) -> tuple[float, float, float]:
    """The schedule's definition: scan the points in order, stop at the first that starts after k."""
    cmd = s.commands[0]
    for point in s.commands:
        if to_step(point.t_s, s.comm_step_s) <= k:
            cmd = point
        else:
            break
    return cmd.vx_des, cmd.vy_des, cmd.yaw_rate_des


def linear_push(s: Scenario, k: int) -> tuple[float, float, float]:
    """The pushes' definition: every push active over [k0, k0 + n), summed from 0.0 in file order."""
    fx = fy = fz = 0.0
    for p in s.pushes:
        k0 = to_step(p.t_s, s.comm_step_s)
        k1 = k0 + to_step(p.duration_s, s.comm_step_s)
        if k0 <= k < k1:
            fx += p.force_n[0]
            fy += p.force_n[1]
            fz += p.force_n[2]
    return (fx, fy, fz)


def scenario(commands, pushes, duration_s=10.0) -> Scenario:
    return Scenario(name="s", description="", duration_s=duration_s, model="menagerie", comm_step_s=H, seed=1,
                    commands=tuple(commands), arms=(Arm("adaptive", ()),), pushes=tuple(pushes))


# forces with many significant bits and signed zeros: a different summation order would show
force = st.floats(-2000.0, 2000.0, allow_nan=False) | st.sampled_from([0.0, -0.0, 0.1, 0.2, 0.3, 1e-17])
commands = st.lists(st.tuples(st.integers(0, 60), st.floats(-2, 2), st.floats(-1, 1), st.floats(-1, 1)),
                    min_size=1, max_size=8)
pushes = st.lists(st.tuples(st.integers(0, 60), st.tuples(force, force, force), st.integers(-2, 30)), max_size=8)


@settings(max_examples=300, deadline=None)
@given(commands=commands, pushes=pushes)
def test_lookup_equals_the_linear_scan_at_every_step(commands, pushes):
    # unsorted and repeated command times and overlapping, empty or negative pushes on purpose:
    # the lookup must agree with the scan even on schedules the validator refuses
    s = scenario([CommandPoint(k * H, vx, vy, w) for k, vx, vy, w in commands],
                 [Push(k * H, f, n * H) for k, f, n in pushes])
    for k in range(-1, 100):
        assert s.command_at_step(k) == linear_command(s, k), k
        got, want = s.push_force_at_step(k), linear_push(s, k)
        assert [x.hex() for x in got] == [x.hex() for x in want], k  # bit for bit, -0.0 included


def test_a_long_schedule_costs_microseconds_per_step():
    # 3600 s with 99,999 pushes and as many commands: the linear scan took ~21 ms per step
    n = 99_999
    s = scenario([CommandPoint(i * 0.035, 0.5 if i % 2 else 0.3) for i in range(n)],
                 [Push(i * 0.035, (10.0, 0.0, 0.0), 0.01) for i in range(n)], duration_s=3600.0)
    steps = range(0, s.n_comm_steps, s.n_comm_steps // 500)  # 500 steps over the whole run
    s.command_at_step(0), s.push_force_at_step(0)  # the indexes are built once per scenario
    t0 = time.perf_counter()
    for k in steps:
        s.command_at_step(k)
        s.push_force_at_step(k)
    per_step = (time.perf_counter() - t0) / len(steps)
    # a bisection over 2e5 entries is ~1 us here; 50 us leaves room for a slow, shared machine
    assert per_step < 50e-6, per_step
    for k in (0, 6, 7, 13, 14, 700_000, s.n_comm_steps - 1):
        assert s.command_at_step(k) == linear_command(s, k)
        assert s.push_force_at_step(k) == linear_push(s, k)
