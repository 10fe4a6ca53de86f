"""Train the RL-HZD policy with Augmented Random Search (ARS V1-t, Mania et al. 2018).

    python -m scenarios.rl_hzd.train [--iterations 40] [--directions 8] [--top 4] [--episode-s 8]
                                     [--workers 2] [--seed 0] [--out scenarios/rl_hzd/policy.json]

On the nominal Cassie (Menagerie model, nominal controller, no perturbation), each episode
walks ``--episode-s`` seconds (default ``EPISODE_S``) with two commands drawn from the episode's seed: forward
speed uniform in [0, 1] m/s, lateral in [-0.2, 0.2] m/s, the second from half-time.
The reward per 10 ms communication step, from ``REWARD_FROM_S`` on, is
``exp(-(e_vx/0.2)^2 - (e_vy/0.2)^2)`` (step-averaged forward error, filtered lateral error,
m/s): in (0, 1], so a fall (which ends the episode) always costs reward.

Every random draw comes from ``--seed``: the directions of iteration i from
``SeedSequence([seed, i])``, the episode commands from ``SeedSequence([seed, i, j])``;
the same seed gives the same policy with any ``--workers``.  Writes the policy JSON (weights,
settings, curve, wall time) and a training-curve plot beside it (``--plot``).
"""
from __future__ import annotations

import logging
import math
import multiprocessing
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from scenarios.lang.cmdline import Parser
from scenarios.rl_hzd.policy import DEFAULT_POLICY, FEATURE_NAMES, HzdPolicy, save_policy
from plant.constants import OFFSET_NAMES

log = logging.getLogger(__name__)

EPISODE_S = 8.0
MAX_EPISODE_S = 600.0
COMM_STEP_S = 0.01
PLANT_STEPS_PER_COMM = 20          # 0.5 ms plant steps
REWARD_FROM_S = 1.5                # after the stand and weight shift (0.8 s) and first steps
ERROR_SCALE_MPS = 0.2
VX_RANGE_MPS = (0.0, 1.0)
VY_RANGE_MPS = (-0.2, 0.2)
EVAL_EPISODES = 4                  # fixed seeds for the training curve


@dataclass(frozen=True)
class ArsSettings:
    iterations: int = 40
    directions: int = 8
    top: int = 4
    step_size: float = 0.002       # rad per unit feature, per iteration (before 1/sigma_R)
    noise: float = 0.005           # rad: a 0.05 rad constant swing-hip offset already trips it
    seed: int = 0
    model: str = "menagerie"
    episode_s: float = EPISODE_S   # s; must exceed REWARD_FROM_S


def _commands(seed_words, episode_s: float) -> list[tuple[float, float, float]]:
    rng = np.random.default_rng(np.random.SeedSequence(list(seed_words)))
    return [(t, float(rng.uniform(*VX_RANGE_MPS)), float(rng.uniform(*VY_RANGE_MPS)))
            for t in (0.0, episode_s / 2)]


_MODEL_CACHE: dict = {}


def _walker(model_source: str):
    from plant.model import load_model
    from plant.sim import CassieWalker

    if model_source not in _MODEL_CACHE:
        _MODEL_CACHE[model_source] = load_model(model_source)
    return CassieWalker(_MODEL_CACHE[model_source])


def episode_return(weights: np.ndarray, seed_words, model_source: str = "menagerie",
                   episode_s: float = EPISODE_S) -> float:
    """Mean reward per communication step of one episode (0 for steps after a fall)."""
    from fmu_src.core.avr_params import RegulatorInputs

    walker, policy = _walker(model_source), HzdPolicy(weights)
    commands = _commands(seed_words, episode_s)
    n_steps = round(episode_s / COMM_STEP_S)
    total = 0.0
    for k in range(n_steps):
        t = k * COMM_STEP_S
        for t_cmd, vx, vy in commands:
            if math.isclose(t, t_cmd):
                walker.set_command(vx, vy)
        u = walker.regulator_inputs()
        inputs = RegulatorInputs(vx_des=walker.vx_des, vy_des=walker.vy_des, **u)
        walker.set_offsets(policy.step(inputs, COMM_STEP_S))
        walker.advance(PLANT_STEPS_PER_COMM)
        if t < REWARD_FROM_S:
            continue
        if walker.fell():
            break
        e_vx, e_vy = u["vx"] - walker.vx_des, u["vy"] - walker.vy_des
        total += math.exp(-(e_vx / ERROR_SCALE_MPS) ** 2 - (e_vy / ERROR_SCALE_MPS) ** 2)
    return total / (n_steps - round(REWARD_FROM_S / COMM_STEP_S))


def _task(args) -> float:
    weights, seed_words, model, episode_s = args
    return episode_return(weights, seed_words, model, episode_s)


def _iteration(pool, theta, it: int, s: ArsSettings) -> tuple[np.ndarray, float]:
    rng = np.random.default_rng(np.random.SeedSequence([s.seed, it]))
    deltas = rng.standard_normal((s.directions,) + theta.shape)
    tasks = []
    for j, d in enumerate(deltas):
        words = (s.seed, it, j)   # the same episode for +d and -d (common random numbers)
        tasks += [(theta + s.noise * d, words, s.model, s.episode_s), (theta - s.noise * d, words, s.model, s.episode_s)]
    returns = np.array(pool.map(_task, tasks)).reshape(s.directions, 2)
    best = np.argsort(-returns.max(axis=1), kind="stable")[: s.top]
    sigma = returns[best].std() or 1.0
    step = sum((returns[j, 0] - returns[j, 1]) * deltas[j] for j in best)
    return theta + s.step_size / (s.top * sigma) * step, float(returns.mean())


def evaluate(pool, theta, s: ArsSettings) -> float:
    """Mean return on the fixed evaluation episodes (seed words (seed, -1, j))."""
    tasks = [(theta, (s.seed, 2 ** 31, j), s.model, s.episode_s) for j in range(EVAL_EPISODES)]
    return float(np.mean(pool.map(_task, tasks)))


def train(s: ArsSettings, workers: int) -> tuple[np.ndarray, list[dict], float]:
    theta = np.zeros((len(OFFSET_NAMES), len(FEATURE_NAMES)))
    curve = []
    t0 = time.perf_counter()
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(workers) as pool:
        curve.append({"iteration": 0, "eval_return": evaluate(pool, theta, s), "mean_return": None})
        for it in range(1, s.iterations + 1):
            theta, mean_ret = _iteration(pool, theta, it, s)
            row = {"iteration": it, "mean_return": mean_ret,
                   "eval_return": evaluate(pool, theta, s) if it % 5 == 0 or it == s.iterations else None}
            curve.append(row)
            log.info("iteration %d: mean return %.4f eval %s (%.0f s)", it, mean_ret,
                     row["eval_return"], time.perf_counter() - t0)
    return theta, curve, time.perf_counter() - t0


def plot_curve(curve: list[dict], path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.5))
    it = [r["iteration"] for r in curve if r["mean_return"] is not None]
    ax.plot(it, [r["mean_return"] for r in curve if r["mean_return"] is not None],
            label="mean return of the perturbed policies")
    ev = [(r["iteration"], r["eval_return"]) for r in curve if r["eval_return"] is not None]
    ax.plot(*zip(*ev), "o-", label=f"policy on {EVAL_EPISODES} fixed episodes")
    ax.set_xlabel("ARS iteration")
    ax.set_ylabel("mean reward per step (1 = perfect)")
    ax.set_title("RL-HZD baseline: ARS on the nominal Cassie")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None) -> int:
    ap = Parser(prog="python -m scenarios.rl_hzd.train", description=__doc__.split("\n")[0])
    for f in ArsSettings.__dataclass_fields__.values():
        ap.add_argument("--" + f.name.replace("_", "-"), type=type(f.default), default=f.default)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=DEFAULT_POLICY)
    ap.add_argument("--plot", type=Path, default=None, help="training curve PNG (default: beside --out)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    s = ArsSettings(**{k: getattr(args, k) for k in ArsSettings.__dataclass_fields__})
    problems = [f"--{k} {getattr(s, k)}: must be >= 1" for k in ("iterations", "directions", "top")
                if getattr(s, k) < 1]
    if not REWARD_FROM_S < s.episode_s <= MAX_EPISODE_S:
        problems.append(f"--episode-s {s.episode_s}: must be > {REWARD_FROM_S} (the reward starts there) and <= {MAX_EPISODE_S}")
    if s.top > s.directions:
        problems.append(f"--top {s.top}: must be <= --directions {s.directions}")
    if args.workers < 1:
        problems.append(f"--workers {args.workers}: must be >= 1")
    if problems:
        ap.error("; ".join(problems))
    theta, curve, wall = train(s, args.workers)
    settings = {**asdict(s), "reward_from_s": REWARD_FROM_S,
                "vx_range_mps": VX_RANGE_MPS, "vy_range_mps": VY_RANGE_MPS,
                "error_scale_mps": ERROR_SCALE_MPS, "wall_s": round(wall, 1), "workers": args.workers}
    save_policy(args.out, theta, settings, curve)
    plot_curve(curve, args.plot or args.out.with_suffix(".png"))
    log.info("wrote %s (%.0f s)", args.out, wall)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
