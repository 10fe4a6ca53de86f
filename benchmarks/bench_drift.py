"""Parameter drift of the learned weights on a long walk with changing commands (issue 25).

The setup: torso 20 kg, torso COM offset (+0.05, -0.03, 0) m, every joint's damping x3,
flat ground; the command changes every 10 s to a seeded draw of vx in [0, 1] m/s and vy in
[-0.2, 0.2] m/s; the regulator core in the loop (``inprocess``: the same bits as the FMUs,
see tests/native/test_native_crosscheck.py).  For every variant (a set of regulator parameter
overrides) and network seed it prints, per window: the mean |step-averaged vx - command|
(m/s), the mean |Psi_x| (rad), the mean swing of Psi_x within a step (rad), and at the window's end the Euclidean norm of each weight
row (x, y, pitch, roll; rad/Hz); then whether and when the robot fell.

    python benchmarks/bench_drift.py                       # plain rule, seeds 1 2 3, 600 s
    python benchmarks/bench_drift.py --variant leakage --duration 300 --seeds 1
    python benchmarks/bench_drift.py --variant all --json drift.json
    python benchmarks/bench_drift.py --variant defaults --require-stable   # the 10-minute check

Variants (``VARIANTS``): plain (the paper's rule: no leakage), leakage (uniform,
``leakage_mode`` 0), leakage_kept_output (``leakage_mode`` 1: only what the current rates do
not use leaks); ``defaults`` runs the shipped parameter defaults, ``pd_only`` the
PD regulator alone (adaptation off).
"""
from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from scenarios.cosim import master  # noqa: E402
from scenarios.lang import spec  # noqa: E402
from scenarios.results import metrics  # noqa: E402
from scenarios.cosim.regulators import InProcessRegulator  # noqa: E402

log = logging.getLogger("bench_drift")

#: The remedy (leakage) off: the paper's plain PES rule.
PLAIN = {"leakage_per_s": 0.0}
VARIANTS = {
    "plain": PLAIN,
    "leakage": {**PLAIN, "leakage_per_s": 0.01, "leakage_mode": 0},
    "leakage_kept_output": {**PLAIN, "leakage_per_s": 0.01, "leakage_mode": 1},
    "defaults": {},
    "pd_only": {"adaptation_enabled": False},
}
WEIGHT_ROWS = ("x", "y", "pitch", "roll")
#: The weight norms are sampled this often (s); a window's end is a multiple of it.
NORM_EVERY_S = 10.0


def drift_scenario(seed: int, duration_s: float, overrides: dict, *, command_seed: int = 25,
                   change_every_s: float = 10.0, pushes: bool = False) -> dict:
    """The issue's drift setup as a scenario document (``seed``: the regulator's network seed)."""
    rng = np.random.default_rng(command_seed)
    n = int(math.ceil(duration_s / change_every_s))
    commands = [{"t_s": change_every_s * k, "vx_des": round(float(rng.uniform(0.0, 1.0)), 3),
                 "vy_des": round(float(rng.uniform(-0.2, 0.2)), 3)} for k in range(n)]
    doc = {
        "name": f"drift_seed{seed}", "description": "long walk, command changing every 10 s",
        "duration_s": float(duration_s), "model": "menagerie", "comm_step_s": 0.005, "seed": seed,
        "perturbation_t_s": 0.0, "torso_mass_kg": 20.0, "torso_com_offset_m": [0.05, -0.03, 0.0],
        "joint_damping_scale": 3.0, "compare": ["adaptive"], "command": commands,
    }
    if overrides:
        doc["regulator"] = dict(overrides)
    if pushes:  # one 25 N, 0.1 s push every 60 s, its direction turning by 90 degrees each time
        doc["push"] = [{"t_s": 60.0 * k + 35.0, "duration_s": 0.1,
                        "force_n": [25.0 * math.cos(k * math.pi / 2), 25.0 * math.sin(k * math.pi / 2), 0.0]}
                       for k in range(int(duration_s // 60.0))]
    return doc


class WeightRecorder(InProcessRegulator):
    """The in-process regulator that also records its weight-row norms every ``every_s``."""

    def __init__(self, every_s: float) -> None:
        super().__init__()
        self.every_s = every_s
        self.samples: list[tuple[float, list[float]]] = []
        self._regulator = None

    def start(self, parameters, t0, t_stop):
        super().start(parameters, t0, t_stop)
        self._regulator = self._step_fn.__self__
        self._next = t0 + self.every_s

    def step(self, t, h, inputs):
        out = super().step(t, h, inputs)
        if t + h >= self._next - 1e-9:  # (1e-9 s: below the 5 ms communication step's rounding)
            weights = self._regulator.state.weights
            self.samples.append((t + h, np.sqrt(np.sum(weights * weights, axis=1)).tolist()))
            self._next += self.every_s
        return out


def within_step_swing(rows, column: str) -> float:
    """Mean over the steps of ``rows`` of (max - min) of ``column`` within the step: how much
    the output follows the velocity's swing inside a step rather than its step average."""
    index = rows["in_step_index"]
    starts = np.r_[0, np.nonzero(np.diff(index))[0] + 1, len(index)]
    values = rows[column]
    swings = [np.ptp(values[a:b]) for a, b in zip(starts[:-1], starts[1:]) if b - a > 1]
    return float(np.mean(swings)) if swings else 0.0


def run_one(seed: int, duration_s: float, overrides: dict, *, window_s: float = 100.0,
            pushes: bool = False) -> dict:
    """One walk; per-window errors, |Psi_x| and weight norms, fall time."""
    scenario = spec.parse_scenario(drift_scenario(seed, duration_s, overrides, pushes=pushes))
    recorder = WeightRecorder(NORM_EVERY_S)
    started = time.perf_counter()
    result = master.run_arm(scenario, scenario.arms[0], recorder)
    wall = time.perf_counter() - started
    rows = result.rows
    ex, _ = metrics.velocity_errors(rows)
    t = rows["t"]
    windows = []
    for k in range(int(round(duration_s / window_s))):
        inside = (t >= k * window_s) & (t < (k + 1) * window_s)
        if not inside.any():
            break
        norms = next((n for ts, n in recorder.samples if abs(ts - (k + 1) * window_s) < 1e-6), None)
        windows.append({"t0_s": k * window_s, "err_vx": float(np.mean(np.abs(ex[inside]))),
                        "psi_x": float(np.mean(np.abs(rows["out_psi_x"][inside]))),
                        "psi_x_swing": within_step_swing(rows[inside], "out_psi_x"),
                        "weight_norms": norms})
    return {"seed": seed, "fell": bool(result.fell), "t_fall_s": result.t_fall_s,
            "fall_reason": result.fall_reason, "wall_s": wall, "windows": windows,
            "overrides": overrides, "window_s": window_s,
            "norms": [[ts, *n] for ts, n in recorder.samples]}


def print_run(variant: str, run: dict) -> None:
    fell = f"FELL at {run['t_fall_s']:.1f} s ({run['fall_reason']})" if run["fell"] else "walked"
    print(f"{variant} seed {run['seed']}: {fell}; wall {run['wall_s']:.0f} s")
    print("  window      |e_vx| m/s   |Psi_x| rad   Psi_x swing rad   |w| x / y / pitch / roll (rad/Hz)")
    for w in run["windows"]:
        norms = " / ".join(f"{v:.2e}" for v in w["weight_norms"]) if w["weight_norms"] else "-"
        print(f"  {w['t0_s']:5.0f}-{w['t0_s'] + run['window_s']:<5.0f}  {w['err_vx']:.3f}        {w['psi_x']:.3f}"
              f"         {w['psi_x_swing']:.4f}            {norms}")


#: The stated bound of ``--require-stable`` (the 10-minute version of the 30-minute long tests):
#: no fall; no 100 s window after the first has a mean error above ERROR_BOUND_MPS; no weight
#: row's norm at the end exceeds NORM_GROWTH_BOUND times its largest value at 200-400 s.
ERROR_BOUND_MPS = 0.10
NORM_GROWTH_BOUND = 1.2


def stability_problems(run: dict) -> list[str]:
    """What breaks the stated bound in ``run`` (empty: it holds)."""
    problems = []
    if run["fell"]:
        problems.append(f"fell at {run['t_fall_s']:.1f} s")
    worst = max((w["err_vx"] for w in run["windows"][1:]), default=0.0)
    if worst > ERROR_BOUND_MPS:
        problems.append(f"window error {worst:.3f} > {ERROR_BOUND_MPS} m/s")
    norms = np.array(run["norms"])
    if len(norms) and norms[-1, 0] >= 400.0:
        middle = norms[(norms[:, 0] >= 200.0) & (norms[:, 0] <= 400.0), 1:].max(axis=0)
        if np.any(norms[-1, 1:] > NORM_GROWTH_BOUND * middle):
            problems.append(f"weight norms {norms[-1, 1:].tolist()} > {NORM_GROWTH_BOUND} x {middle.tolist()}")
    return problems


def plot(runs: list[dict], path: Path) -> None:
    """Per-window error and the x row's weight norm over time, one colour per variant (one
    line per seed; a cross where a walk fell)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    variants = list(dict.fromkeys(run["variant"] for run in runs))
    colours = dict(zip(variants, plt.rcParams["axes.prop_cycle"].by_key()["color"]))
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.5, 6.0), sharex=True)
    for run in runs:
        c = colours[run["variant"]]
        label = run["variant"] if run["seed"] == min(r["seed"] for r in runs if r["variant"] == run["variant"]) else None
        mids = [w["t0_s"] + run["window_s"] / 2 for w in run["windows"]]
        top.plot(mids, [w["err_vx"] for w in run["windows"]], "o-", color=c, lw=1, ms=3, label=label)
        norms = np.array(run.get("norms") or [[w["t0_s"] + run["window_s"], *w["weight_norms"]]
                                                for w in run["windows"] if w["weight_norms"]] or np.zeros((0, 5)))
        bottom.plot(norms[:, 0], norms[:, 1], color=c, lw=1)
        if run["fell"]:
            top.plot([run["t_fall_s"]], [run["windows"][-1]["err_vx"]], "x", color=c, ms=10, mew=2)
            bottom.plot([run["t_fall_s"]], [norms[-1, 1] if len(norms) else 0.0], "x", color=c, ms=10, mew=2)
    top.set_ylabel("mean |step-avg vx - cmd|, m/s")
    top.legend(fontsize=8)
    top.set_title("20 kg torso, COM (+0.05, -0.03) m, damping x3, command every 10 s (x: fall)", fontsize=9)
    bottom.set_ylabel("|w_x| (forward network), rad/Hz")
    bottom.set_xlabel("t, s")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--variant", default="plain", help=f"one of {', '.join(VARIANTS)}, or all")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3], help="network seeds")
    ap.add_argument("--duration", type=float, default=600.0, help="walk length, s")
    ap.add_argument("--window", type=float, default=100.0, help="window length, s")
    ap.add_argument("--pushes", action="store_true", help="a 25 N push every 60 s")
    ap.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE",
                    help="extra regulator overrides on top of the variant")
    ap.add_argument("--json", type=Path, help="also write the numbers here")
    ap.add_argument("--require-stable", action="store_true",
                    help="exit 1 unless every run keeps the stated bound (ERROR_BOUND_MPS, NORM_GROWTH_BOUND)")
    ap.add_argument("--plot", type=Path, metavar="PNG",
                    help="plot the runs of the --json files given as --from (runs nothing)")
    ap.add_argument("--from", dest="sources", type=Path, nargs="*", default=[], metavar="JSON")
    args = ap.parse_args(argv)
    if args.plot:
        plot([run for src in args.sources for run in json.loads(src.read_text())], args.plot)
        return 0
    names = list(VARIANTS) if args.variant == "all" else [args.variant]
    unknown = [n for n in names if n not in VARIANTS]
    if unknown:
        ap.error(f"--variant {unknown[0]!r}: must be one of {', '.join(VARIANTS)} or all")
    extra = {}
    for item in args.set:
        name, _, value = item.partition("=")
        extra[name] = int(value) if value.lstrip('+-').isdigit() else float(value)
    out = []
    for name in names:
        for seed in args.seeds:
            run = run_one(seed, args.duration, {**VARIANTS[name], **extra}, window_s=args.window,
                          pushes=args.pushes)
            run["variant"] = name + "".join(f" {k}={v:g}" for k, v in extra.items())
            print_run(run["variant"], run)
            sys.stdout.flush()
            out.append(run)
            if args.json:  # after every run: a long batch cut short keeps what it measured
                args.json.write_text(json.dumps(out, indent=1))
    if args.require_stable:
        failed = {f"{run['variant']} seed {run['seed']}": stability_problems(run) for run in out}
        failed = {k: v for k, v in failed.items() if v}
        for name, problems in failed.items():
            print(f"NOT STABLE: {name}: {'; '.join(problems)}")
        return 1 if failed else 0
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
