"""The analysis of a campaign folder: statistics per arm, paired comparison, campaign.md.

Over the ``complete`` rows of ``campaign.csv`` (a ``failed`` row is counted, never
averaged in): per arm the fall rate with its 95 % Wilson interval, quantiles of the
steady-state velocity errors of the runs that kept walking, the share that converged;
for the first two arms, the paired comparison sample by sample (the same plant, command
and seed) and the samples where the first arm is not better; the worst samples of each
arm with their scenario files.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from scenarios.campaign.store import CSV_NAME, MANIFEST_NAME, read_rows
from scenarios.campaign.task import COMPLETE

QUANTILES = (0.5, 0.9)
Z95 = 1.959964  # two-sided 95 % normal quantile (Wilson interval)
FLOAT_COLS = ("t_fall_s", "steady_state_error_vx", "steady_state_error_vy", "settled_error_vx", "convergence_time_s",
              "mean_vx_last_s", "mean_vy_last_s", "max_abs_pitch_rad", "max_abs_roll_rad", "sim_s", "wall_s",
              "task_wall_s")


@dataclass
class CampaignData:
    root: Path
    manifest: dict[str, Any]
    rows: list[dict[str, Any]]  # typed
    factors: list[str]

    @property
    def arms(self) -> list[str]:
        return list(self.manifest["arms"])

    @property
    def expected_rows(self) -> int:
        """One row per sample and arm."""
        return self.manifest["n_samples"] * len(self.arms)

    @property
    def failed_rows(self) -> int:
        return sum(r["status"] != COMPLETE for r in self.rows)

    @property
    def complete(self) -> bool:
        """Every sample x arm has a row, and none failed."""
        return len(self.rows) >= self.expected_rows and not self.failed_rows

    @property
    def metric(self) -> str:
        """The error the paired verdicts compare (the campaign file's ``metric``)."""
        return self.manifest.get("metric", "steady_state_error_vx")

    @property
    def replicate_over(self) -> dict[str, Any] | None:
        """The campaign file's ``replicate_over`` (factor, draws, grid cells, its index), if any."""
        return self.manifest.get("replicate_over") or None

    def replicas(self, arm: str) -> list[str]:
        """The replica arms of ``arm``: the campaign file's ``[replicas]``, or with
        ``replicate_over`` the arm on the factor's other values (``ARM@k``, see
        :meth:`verdict_rows`); none by default."""
        over = self.replicate_over
        if over:
            return [f"{arm}@{k}" for k in range(1, over["cells"][over["index"]])]
        return list((self.manifest.get("replicas") or {}).get(arm, ()))

    def verdict_rows(self) -> list[dict[str, Any]]:
        """The rows the verdicts judge: as they are, or with ``replicate_over`` regrouped by
        random draw (:func:`regroup`)."""
        over = self.replicate_over
        return regroup(self.rows, over["draws"], over["cells"], over["index"]) if over else self.rows


def is_campaign_dir(path: Path) -> bool:
    return (Path(path) / MANIFEST_NAME).is_file()


def _typed(row: dict[str, str], factors: Sequence[str]) -> dict[str, Any]:
    out: dict[str, Any] = dict(row)
    for c in FLOAT_COLS:
        out[c] = float(row[c]) if row.get(c) else None
    out["fell"] = {"true": True, "false": False}.get(row.get("fell", ""))
    for f in factors:
        out[f] = _factor_value(row[f])
    return out


def regroup(rows: Sequence[dict[str, Any]], draws: int, cells: Sequence[int], index: int) -> list[dict[str, Any]]:
    """Rows of a campaign with a grid, relabelled so that the verdicts take the cells of
    grid factor ``index`` as replicas. Sample ``i`` is random draw ``i % draws`` in grid cell
    ``i // draws`` (:func:`scenarios.campaign.sampling.draw`; the last grid factor
    varies fastest). Its row keeps every value and becomes sample ``SAMPLE`` (the id of the
    draw's sample on the factor's first value, the other grid factors as they are) and arm
    ``ARM@k`` on the factor's value ``k`` > 0 (``ARM`` on the first)."""
    width = len(rows[0]["sample"]) - 1 if rows else 4
    strides = [math.prod(cells[j + 1:]) for j in range(len(cells))]
    out = []
    for r in rows:
        i = int(r["sample"][1:])
        cell, draw = divmod(i, draws)
        k = (cell // strides[index]) % cells[index]
        first = (cell - k * strides[index]) * draws + draw
        out.append({**r, "sample": f"s{first:0{width}d}", "arm": r["arm"] if k == 0 else f"{r['arm']}@{k}"})
    return out


def _factor_value(text: str) -> Any:
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text, text)


def load(root: Path) -> CampaignData:
    root = Path(root)
    manifest = json.loads((root / MANIFEST_NAME).read_text())
    cols = manifest["columns"]
    factors = cols[2:cols.index("status")]
    rows = [_typed(r, factors) for r in read_rows(root / CSV_NAME, cols)]
    return CampaignData(root, manifest, rows, factors)


# --------------------------------------------------------------------------- statistics
def quantile(values: Sequence[float], q: float) -> float | None:
    """Linear-interpolation quantile (numpy's default); None for no values."""
    if not values:
        return None
    v = sorted(values)
    pos = q * (len(v) - 1)
    lo = math.floor(pos)
    hi = min(lo + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (pos - lo)


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float] | None:
    """The Wilson score interval of a proportion k/n (None for n = 0)."""
    if n == 0:
        return None
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def arm_stats(rows: Sequence[dict[str, Any]], arm: str) -> dict[str, Any]:
    mine = [r for r in rows if r["arm"] == arm]
    done = [r for r in mine if r["status"] == COMPLETE]
    walked = [r for r in done if r["fell"] is False]
    fell = len(done) - len(walked)
    out: dict[str, Any] = {"arm": arm, "rows": len(mine), "complete": len(done), "failed": len(mine) - len(done),
                           "fell": fell, "fall_rate": fell / len(done) if done else None,
                           "fall_ci": wilson(fell, len(done)), "walked": len(walked)}
    for key in ("steady_state_error_vx", "steady_state_error_vy", "settled_error_vx"):
        vals = [r.get(key) for r in walked if r.get(key) is not None]
        out[key] = {**{f"p{int(q * 100)}": quantile(vals, q) for q in QUANTILES}, "max": max(vals, default=None)}
    conv = [r["convergence_time_s"] for r in walked if r["convergence_time_s"] is not None]
    out["converged"] = len(conv)
    out["convergence_p50"] = quantile(conv, 0.5)
    return out


def paired(rows: Sequence[dict[str, Any]], a: str, b: str) -> dict[str, Any]:
    """Arm ``a`` against arm ``b`` on the samples where both are complete."""
    by = {(r["sample"], r["arm"]): r for r in rows if r["status"] == COMPLETE}
    samples = sorted({s for s, arm in by if arm == a and (s, b) in by})
    out = {"a": a, "b": b, "n": len(samples), "both_fell": 0, "only_a_fell": [], "only_b_fell": [],
           "both_walked": 0, "a_lower_vx": 0, "a_lower_vy": 0, "not_better": []}
    diffs, diffs_vy = [], []
    for s in samples:
        ra, rb = by[(s, a)], by[(s, b)]
        if ra["fell"] and rb["fell"]:
            out["both_fell"] += 1
        elif ra["fell"]:
            out["only_a_fell"].append(s)
            out["not_better"].append((s, "fell (the other arm did not)", ra, rb))
        elif rb["fell"]:
            out["only_b_fell"].append(s)
        elif ra["steady_state_error_vx"] is not None and rb["steady_state_error_vx"] is not None:
            out["both_walked"] += 1
            d = ra["steady_state_error_vx"] - rb["steady_state_error_vx"]
            diffs.append(d)
            if d < 0:
                out["a_lower_vx"] += 1
            else:
                out["not_better"].append((s, f"sse_vx {d:+.4f} m/s", ra, rb))
            if ra["steady_state_error_vy"] is not None and rb["steady_state_error_vy"] is not None:
                diffs_vy.append(ra["steady_state_error_vy"] - rb["steady_state_error_vy"])
                out["a_lower_vy"] += diffs_vy[-1] < 0
    out["median_diff_vx"] = quantile(diffs, 0.5)
    out["median_diff_vy"] = quantile(diffs_vy, 0.5)
    out["max_diff_vy"] = max(diffs_vy, default=None)
    return out


#: The share of paired samples the first arm must win for the "beats" verdict.
WIN_SHARE_REQUIRED = 0.9
#: Bootstrap resamples of the paired median difference, and their fixed seed.
BOOTSTRAP_N = 2000
BOOTSTRAP_SEED = 0


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float] | None:
    """The exact (Clopper-Pearson) interval of a proportion k/n: the binomial tails'
    inversion, by bisection on math.comb sums (no scipy). None for n = 0."""
    if n == 0:
        return None
    alpha = 1.0 - level

    def cdf(j: int, p: float) -> float:  # P[X <= j]
        return sum(math.comb(n, i) * p ** i * (1 - p) ** (n - i) for i in range(j + 1))

    def solve(f, target: float) -> float:  # f increasing in p on [0, 1]
        lo, hi = 0.0, 1.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if f(mid) < target else (lo, mid)
        return 0.5 * (lo + hi)

    lower = 0.0 if k == 0 else solve(lambda p: 1.0 - cdf(k - 1, p), alpha / 2)
    upper = 1.0 if k == n else solve(lambda p: 1.0 - cdf(k, p), 1.0 - alpha / 2)
    return lower, upper


def verdicts(rows: Sequence[dict[str, Any]], a: str, b: str, *, metric: str = "steady_state_error_vx",
             replicas_a: Sequence[str] = (), replicas_b: Sequence[str] = ()) -> dict[str, Any]:
    """The two paired claims of ``a`` against ``b`` (e.g. adaptive vs PD-only), as verdicts.

    Each arm runs on every sample once, or R times: itself and its replica arms (the same
    controller under a nuisance change, e.g. a gain 5 % off), replica i of ``a`` paired
    with replica i of ``b``. Near the edge of falling any change of the walk tips a sample
    into a fall or out of one, so the claims are judged on each sample's outcomes over its
    R pairs (with R = 1, on the one run):

    * ``never_falls_where_b_walks``: no sample where ``a`` fell on more than half of its
      replicas and ``b`` on fewer than half (the same majority reading for both arms; the
      samples where it did are listed, with the exact 95 % interval of that rate;
      ``a_fell_some`` lists the samples where ``a`` fell on some replica and ``b`` on none).
    * ``beats``: a pair is contested unless both fell; ``a`` wins it when only ``b`` fell,
      or both walked and ``a``'s ``metric`` is lower. ``a`` wins a sample when it wins more
      than half of the sample's contested pairs; a sample with none is no contest. The
      verdict holds when the wins are at least :data:`WIN_SHARE_REQUIRED` of the contested
      samples; with the exact 95 % interval of the share, and a bootstrap 95 % interval of
      the median ``metric`` difference over the pairs both walked.
    """
    if len(replicas_a) != len(replicas_b):
        raise ValueError(f"{a} has {len(replicas_a)} replicas, {b} {len(replicas_b)}: they pair by position")
    pairs = [(a, b), *zip(replicas_a, replicas_b)]
    by = {(r["sample"], r["arm"]): r for r in rows if r["status"] == COMPLETE}
    samples = sorted({s for s, _ in by if all((s, x) in by for pair in pairs for x in pair)})
    n_pairs = len(pairs)
    out: dict[str, Any] = {"n": len(samples), "replicas": n_pairs, "metric": metric, "contested": 0, "wins": 0,
                           "only_a_fell": [], "a_fell_some": [], "not_won": []}
    diffs: list[float] = []
    falls: list[tuple[list[bool], list[bool]]] = []
    for s in samples:
        fa = [by[(s, x)]["fell"] for x, _ in pairs]
        fb = [by[(s, y)]["fell"] for _, y in pairs]
        falls.append((fa, fb))
        if not any(fb) and any(fa):
            out["a_fell_some"].append((s, sum(fa)))
        if 2 * sum(fa) > n_pairs and 2 * sum(fb) < n_pairs:
            out["only_a_fell"].append(s)
        contested = won = 0
        for (x, y), fell_a, fell_b in zip(pairs, fa, fb):
            if fell_a and fell_b:
                continue
            contested += 1
            ea, eb = by[(s, x)].get(metric), by[(s, y)].get(metric)
            if fell_b:
                won += 1
            elif not fell_a and ea is not None and eb is not None:
                diffs.append(ea - eb)
                won += ea < eb
        if contested:
            out["contested"] += 1
            if 2 * won > contested:
                out["wins"] += 1
            else:
                out["not_won"].append((s, won, contested, sum(fa), sum(fb)))
    contested = out["contested"]
    out.update({
        "win_share": out["wins"] / contested if contested else None,
        "win_ci": clopper_pearson(out["wins"], contested),
        "beats": bool(contested) and out["wins"] >= WIN_SHARE_REQUIRED * contested,
        "never_falls_where_b_walks": not out["only_a_fell"],
        "only_a_fell_ci": clopper_pearson(len(out["only_a_fell"]), len(samples)),
        "only_a_fell_null": swapped_only_a_fell(falls, len(out["only_a_fell"])),
        "median_diff": quantile(diffs, 0.5), "median_diff_ci": bootstrap_median_ci(diffs),
    })
    return out


#: Random relabellings of the arms for the chance level of "never falls where b walks".
SWAPS_N = 2000


def swapped_only_a_fell(falls: Sequence[tuple[Sequence[bool], Sequence[bool]]], observed: int,
                        level: float = 0.95) -> dict[str, float] | None:
    """How many samples the "never falls where b walks" reading lists by chance alone.

    ``falls``: per sample, the fell flags of ``a``'s and ``b``'s runs, paired by position.
    Were the two arms equally likely to be the one that falls on each pair, swapping the
    two runs of a pair would not change the odds; this swaps each pair with probability
    1/2 (:data:`SWAPS_N` times, seed :data:`BOOTSTRAP_SEED`) and counts the samples where
    ``a`` fell on more than half of its runs and ``b`` on fewer than half. Returns the
    mean count, its central ``level`` interval and the share of swaps with at least
    ``observed`` such samples; None without samples."""
    if not falls:
        return None
    import numpy as np

    fa = np.array([a for a, _ in falls], dtype=bool)  # samples x pairs
    fb = np.array([b for _, b in falls], dtype=bool)
    n_pairs = fa.shape[1]
    swap = np.random.default_rng(BOOTSTRAP_SEED).random((SWAPS_N, *fa.shape)) < 0.5
    ka = np.where(swap, fb, fa).sum(axis=2)
    kb = np.where(swap, fa, fb).sum(axis=2)
    counts = ((2 * ka > n_pairs) & (2 * kb < n_pairs)).sum(axis=1)
    return {"mean": float(counts.mean()), "low": float(np.quantile(counts, (1 - level) / 2)),
            "high": float(np.quantile(counts, (1 + level) / 2)), "at_least_observed": float((counts >= observed).mean())}


def mcnemar_exact(k: int, m: int) -> float | None:
    """Two-sided exact McNemar p-value of ``k`` against ``m`` discordant pairs: the
    probability, if either arm were as likely as the other to be the one that fell, of a
    split at least as uneven (binomial with p = 1/2 on k + m pairs). None when no pair
    is discordant."""
    if k + m == 0:
        return None
    return min(1.0, 2.0 * one_sided_exact(max(k, m), min(k, m)))  # the lower tail, by symmetry


#: The confirmation stage's folder inside a campaign folder (a campaign folder itself).
CONFIRM_DIR = "confirm"
#: Level of the confirmation test: one-sided exact McNemar per listed draw, Holm's step-down
#: over the listed draws, so the chance of confirming any draw where the two arms are in truth
#: equally likely to fall is at most this.
CONFIRM_ALPHA = 0.05


def one_sided_exact(k: int, m: int) -> float:
    """P[X >= k] for X ~ Binomial(k + m, 1/2): the chance, were either arm as likely as the
    other to be the one that falls, that at least ``k`` of the ``k + m`` discordant pairs go
    against the first arm (1 without discordant pairs)."""
    n = k + m
    return sum(math.comb(n, i) for i in range(k, n + 1)) / 2 ** n if n else 1.0


def holm(pvalues: Sequence[float], alpha: float) -> list[bool]:
    """Holm's step-down: which of ``pvalues`` are rejected at family-wise level ``alpha``."""
    order = sorted(range(len(pvalues)), key=lambda i: pvalues[i])
    rejected = [False] * len(pvalues)
    for rank, i in enumerate(order):
        if pvalues[i] > alpha / (len(pvalues) - rank):
            break
        rejected[i] = True
    return rejected


def confirmation(listed: Sequence[str], stage_rows: Sequence[dict[str, Any]], of: dict[str, str], a: str, b: str,
                 runs: int, alpha: float = CONFIRM_ALPHA) -> dict[str, Any]:
    """The verdict "``a`` never falls where ``b`` walks" after its confirmation stage.

    The majority reading of the campaign's replicas lists draws by chance too: at the edge
    of falling, two equally robust controllers each fall on about half of a draw's runs, and
    the reading then lists the draw for one of them one time in four. Every listed draw was
    therefore run again on ``runs`` fresh replicas (``stage_rows``; ``of`` maps each stage
    sample to its draw), ``a`` paired with ``b`` on each. A draw is *confirmed* when its
    fresh pairs where only ``a`` fell outnumber those where only ``b`` fell beyond chance:
    one-sided exact McNemar p (:func:`one_sided_exact`), Holm's step-down over the listed
    draws at ``alpha``. Only fresh runs count: the runs that listed a draw were selected for
    going against ``a``.

    Returns per draw its counts, p and whether it is confirmed; ``complete`` when every
    listed draw has ``runs`` complete pairs; ``holds`` when complete and none is confirmed
    (a confirmed draw fails the verdict even before the stage is complete)."""
    by = {(r["sample"], r["arm"]): r for r in stage_rows if r["status"] == COMPLETE}
    draws = []
    for d in listed:
        pairs = [(by[(s, a)]["fell"], by[(s, b)]["fell"]) for s in sorted(of) if of[s] == d
                 and (s, a) in by and (s, b) in by]
        k = sum(fa and not fb for fa, fb in pairs)
        m = sum(fb and not fa for fa, fb in pairs)
        draws.append({"draw": d, "runs": len(pairs), "a_fell": sum(fa for fa, _ in pairs),
                      "b_fell": sum(fb for _, fb in pairs), "only_a": k, "only_b": m, "p": one_sided_exact(k, m)})
    for x, confirmed in zip(draws, holm([x["p"] for x in draws], alpha)):
        x["confirmed"] = confirmed
    complete = all(x["runs"] == runs for x in draws)
    confirmed = [x["draw"] for x in draws if x["confirmed"]]
    return {"draws": draws, "runs": runs, "alpha": alpha, "complete": complete, "confirmed": confirmed,
            "holds": complete and not confirmed}


def load_confirmation(root: Path) -> CampaignData | None:
    """The confirmation stage's folder of campaign folder ``root``, if it has one."""
    stage = Path(root) / CONFIRM_DIR
    return load(stage) if is_campaign_dir(stage) else None


def fall_agreement(rows: Sequence[dict[str, Any]], b: str, arms: Sequence[str]) -> list[dict[str, Any]]:
    """Every arm of ``arms`` other than ``b`` against ``b``, counted on falls only: the
    samples where it fell and ``b`` walked, the samples where ``b`` fell and it walked,
    and the exact McNemar p-value of that split. An arm that differs from ``b`` only by a
    small change of one gain shows how many such samples chance alone gives: near the
    edge of falling, any change of the walk tips some samples either way."""
    out = []
    for arm in arms:
        if arm == b:
            continue
        p = paired(rows, arm, b)
        k, m = len(p["only_a_fell"]), len(p["only_b_fell"])
        out.append({"arm": arm, "n": p["n"], "only_arm_fell": p["only_a_fell"], "only_b_fell": p["only_b_fell"],
                    "p_value": mcnemar_exact(k, m)})
    return out


def bootstrap_median_ci(values: Sequence[float], level: float = 0.95) -> tuple[float, float] | None:
    """Percentile bootstrap interval of the median (:data:`BOOTSTRAP_N` resamples, fixed seed)."""
    if not values:
        return None
    import numpy as np

    rng = np.random.default_rng(BOOTSTRAP_SEED)
    v = np.asarray(values, dtype=float)
    medians = np.median(v[rng.integers(0, len(v), (BOOTSTRAP_N, len(v)))], axis=1)
    return (float(np.quantile(medians, (1 - level) / 2)), float(np.quantile(medians, (1 + level) / 2)))


def worst(rows: Sequence[dict[str, Any]], arm: str, k: int = 5) -> list[dict[str, Any]]:
    """Falls first (earliest first), then the largest sse_vx."""
    done = [r for r in rows if r["arm"] == arm and r["status"] == COMPLETE]
    return sorted(done, key=lambda r: (0, r["t_fall_s"] or 0.0) if r["fell"]
                  else (1, -(r["steady_state_error_vx"] or 0.0)))[:k]
