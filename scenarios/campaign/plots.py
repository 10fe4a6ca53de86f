"""The campaign's plots (matplotlib, Agg), written next to ``campaign.md``.

- ``fall_rate.png``: fall rate per arm with its 95 % Wilson interval;
- ``errors.png``: the steady-state errors per arm (violin + box, every run a dot);
- ``factors.png``: sse_vx against each factor, one colour per arm, falls on a top band;
- ``paired.png``: the first arm's sse_vx against the second's, sample by sample;
- ``speeds.png`` (a campaign that varies ``vx_des`` or ``vy_des``): the achieved speed
  (mean over the last seconds) against the commanded one, per arm; falls marked.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from scenarios.campaign import analysis
from scenarios.campaign.task import COMPLETE

SSE_KEYS = (("steady_state_error_vx", "sse_vx (m/s)"), ("steady_state_error_vy", "sse_vy (m/s)"))
#: Command factors of ``speeds.png`` and the metric each is achieved as.
SPEED_FACTORS = (("vx_des", "mean_vx_last_s"), ("vy_des", "mean_vy_last_s"))
#: The paired comparison's plot (campaign.md shows it in its own section).
PAIRED = "paired.png"


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, root: Path, name: str) -> str:
    fig.tight_layout()
    fig.savefig(root / name, dpi=90)
    _plt().close(fig)
    return name


def _colors(arms: Sequence[str]) -> dict[str, str]:
    cycle = _plt().rcParams["axes.prop_cycle"].by_key()["color"]
    return {a: cycle[i % len(cycle)] for i, a in enumerate(arms)}


def fall_rate(data: analysis.CampaignData) -> str:
    plt = _plt()
    stats = [analysis.arm_stats(data.rows, a) for a in data.arms]
    fig, ax = plt.subplots(figsize=(1.6 + 1.4 * len(stats), 3.6))
    colors = _colors(data.arms)
    for i, s in enumerate(stats):
        if s["fall_rate"] is None:
            continue
        lo, hi = s["fall_ci"]
        ax.bar(i, 100 * s["fall_rate"], color=colors[s["arm"]], alpha=0.8)
        ax.errorbar(i, 100 * s["fall_rate"], yerr=[[100 * (s["fall_rate"] - lo)], [100 * (hi - s["fall_rate"])]],
                    color="k", capsize=6)
        ax.text(i, 100 * hi + 2, f"{s['fell']}/{s['complete']}", ha="center", fontsize=9)
    ax.set_xticks(range(len(stats)), [s["arm"] for s in stats], rotation=20, ha="right")  # long arm names
    ax.set_ylim(0, 110)
    ax.set_ylabel("fall rate (%), 95 % CI")
    ax.set_title(f"{data.manifest['name']}: falls per arm")
    ax.grid(axis="y", alpha=0.3)
    return _save(fig, data.root, "fall_rate.png")


def _walked(data: analysis.CampaignData, arm: str, key: str) -> list[float]:
    return [r[key] for r in data.rows if r["arm"] == arm and r["status"] == COMPLETE and r["fell"] is False
            and r[key] is not None]


def errors(data: analysis.CampaignData) -> str:
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(4 + 1.6 * len(data.arms), 3.8))
    rng = np.random.default_rng(0)  # dot jitter only
    colors = _colors(data.arms)
    for ax, (key, label) in zip(axes, SSE_KEYS):
        series = [_walked(data, a, key) for a in data.arms]
        pos = [i for i, s in enumerate(series) if len(s) >= 2]
        if pos:
            ax.violinplot([series[i] for i in pos], positions=pos, showextrema=False)
            ax.boxplot([series[i] for i in pos], positions=pos, widths=0.15, showfliers=False)
        for i, s in enumerate(series):
            ax.scatter(i + rng.uniform(-0.08, 0.08, len(s)), s, s=8, color=colors[data.arms[i]], alpha=0.6, zorder=3)
        ax.set_xticks(range(len(data.arms)), data.arms, rotation=20, ha="right")  # long arm names
        ax.set_ylabel(label)
        ax.grid(axis="y", alpha=0.3)
    axes[0].set_title("runs that kept walking", fontsize=9)
    fig.suptitle(f"{data.manifest['name']}: steady-state velocity error per arm")
    return _save(fig, data.root, "errors.png")


def _axis_values(rows: Sequence[dict[str, Any]], factor: str) -> tuple[list[float], list[str] | None]:
    vals = [r[factor] for r in rows]
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
        return [float(v) for v in vals], None
    labels = sorted({str(v) for v in vals})
    return [float(labels.index(str(v))) for v in vals], labels


def factors(data: analysis.CampaignData) -> str:
    plt = _plt()
    n = len(data.factors)
    ncols = min(3, n)
    nrows = (n + ncols - 1) // ncols
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.2 * ncols, 3.2 * nrows), squeeze=False)
    colors = _colors(data.arms)
    done = [r for r in data.rows if r["status"] == COMPLETE]
    walked_sse = [r["steady_state_error_vx"] for r in done if r["steady_state_error_vx"] is not None]
    top = 1.1 * max(walked_sse, default=1.0)
    for idx, factor in enumerate(data.factors):
        ax = axes[idx // ncols][idx % ncols]
        for arm in data.arms:
            mine = [r for r in done if r["arm"] == arm]
            xs, labels = _axis_values(mine, factor)
            ys = [top if r["fell"] else r["steady_state_error_vx"] for r in mine]
            marker = ["x" if r["fell"] else "o" for r in mine]
            for m in ("o", "x"):
                sel = [i for i, mk in enumerate(marker) if mk == m and ys[i] is not None]
                ax.scatter([xs[i] for i in sel], [ys[i] for i in sel], s=14, marker=m, color=colors[arm],
                           alpha=0.7, label=arm if m == "o" else None)
            if labels:
                ax.set_xticks(range(len(labels)), labels, fontsize=7, rotation=20)
        ax.axhline(top, color="grey", lw=0.6, ls=":")
        ax.set_xlabel(factor)
        ax.set_ylabel("sse_vx (m/s); x on top: fell")
        ax.grid(alpha=0.3)
    for idx in range(n, nrows * ncols):
        axes[idx // ncols][idx % ncols].axis("off")
    axes[0][0].legend(fontsize=8)
    fig.suptitle(f"{data.manifest['name']}: steady-state error vs each factor")
    return _save(fig, data.root, "factors.png")


def paired(data: analysis.CampaignData) -> str | None:
    if len(data.arms) < 2:
        return None
    plt = _plt()
    a, b = data.arms[:2]
    key = data.metric  # the error the verdicts compare
    label = "sse_vx" if key == "steady_state_error_vx" else key.replace("_error", "")
    by = {(r["sample"], r["arm"]): r for r in data.rows if r["status"] == COMPLETE}
    pairs = [(by[(s, a)], by[(s, b)]) for s, arm in by if arm == a and (s, b) in by]
    both = [(ra.get(key), rb.get(key)) for ra, rb in pairs
            if not ra["fell"] and not rb["fell"] and ra.get(key) is not None and rb.get(key) is not None]
    fig, ax = plt.subplots(figsize=(4.6, 4.4))
    if both:
        xs, ys = zip(*((y, x) for x, y in both))
        ax.scatter(xs, ys, s=14, alpha=0.7)
        lim = 1.05 * max(max(xs), max(ys))
        ax.plot([0, lim], [0, lim], "k--", lw=0.8)
        ax.set_xlim(0, lim)
        ax.set_ylim(0, lim)
    n_fa = sum(1 for ra, rb in pairs if ra["fell"] and not rb["fell"])
    n_fb = sum(1 for ra, rb in pairs if rb["fell"] and not ra["fell"])
    ax.set_xlabel(f"{b} {label} (m/s)")
    ax.set_ylabel(f"{a} {label} (m/s)")
    ax.set_title(f"below the line: {a} better\n(not shown: only {a} fell {n_fa}, only {b} fell {n_fb})", fontsize=9)
    ax.grid(alpha=0.3)
    return _save(fig, data.root, PAIRED)


def speeds(data: analysis.CampaignData) -> str | None:
    """Achieved vs commanded speed for each command factor the campaign varies."""
    varied = [(f, m) for f, m in SPEED_FACTORS if f in data.factors]
    if not varied:
        return None
    plt = _plt()
    fig, axes = plt.subplots(1, len(varied), figsize=(4.8 * len(varied), 4.4), squeeze=False)
    colors = _colors(data.arms)
    done = [r for r in data.rows if r["status"] == COMPLETE]
    for ax, (factor, metric) in zip(axes[0], varied):
        cmds = sorted({float(r[factor]) for r in done})
        span = (cmds[-1] - cmds[0]) or 1.0
        for i, arm in enumerate(data.arms):
            dx = (i - (len(data.arms) - 1) / 2) * 0.012 * span  # side by side at each command
            walked = [r for r in done if r["arm"] == arm and not r["fell"] and r[metric] is not None]
            fell = [r for r in done if r["arm"] == arm and r["fell"]]
            ax.scatter([float(r[factor]) + dx for r in walked], [r[metric] for r in walked], s=14,
                       color=colors[arm], alpha=0.7, label=arm)
            if fell:
                ax.scatter([float(r[factor]) + dx for r in fell], [cmds[0] - 0.1 * span] * len(fell), s=24,
                           marker="x", color=colors[arm], label=f"{arm}: fell ({len(fell)})")
        ax.plot([cmds[0], cmds[-1]], [cmds[0], cmds[-1]], "k--", lw=0.8, label="achieved = commanded")
        ax.set_xlabel(f"commanded {factor} (m/s)")
        ax.set_ylabel(f"achieved ({metric}, m/s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"{data.manifest['name']}: commanded vs achieved speed")
    return _save(fig, data.root, "speeds.png")


def write_plots(data: analysis.CampaignData) -> list[str]:
    if not any(r["status"] == COMPLETE for r in data.rows):
        return []
    written = [fall_rate(data), errors(data), factors(data), paired(data), speeds(data)]
    return [w for w in written if w]
