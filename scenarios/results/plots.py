"""The three PNG plots of one scenario's results (matplotlib, Agg backend).

``velocity.png``: step-averaged velocity against the command per arm (faint: the
instantaneous velocity; a scenario that commands a turn gets a third panel, the yaw rate
averaged over the last second against its command); ``psi.png``: the networks' outputs
and the joint offsets; ``torso.png``: torso pitch and roll.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from scenarios.results import metrics
from scenarios.lang.scenario import Scenario

PLOTS = ("velocity.png", "psi.png", "torso.png")
PSI_NAMES = ("psi_x", "psi_y", "psi_pitch", "psi_roll")
#: The yaw-rate panel's trailing mean, s (a few steps: the heading sways with every step).
YAW_RATE_MEAN_S = 1.0
#: Titles at the top of their axes: placed, not moved clear of tick labels at each draw
#: (there are none above the axes here; the search was a tenth of the plotting time).
TITLE_Y = 1.0
#: zlib's level for the PNGs (Pillow's default is 6).
PNG_COMPRESS_LEVEL = 1


def write_plots(out_dir: Path, scenario: Scenario, results: Sequence[Any]) -> list[str]:
    """velocity.png (velocity vs command per arm), psi.png (Psi and joint offsets), torso.png."""
    import matplotlib

    results = [r for r in results if len(r.rows)]
    if not results:
        return []
    colors = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    written = []
    for name, draw in zip(PLOTS, (_velocity, _psi, _torso)):
        fig = draw(scenario, results, colors)
        # zlib level 1: encoding took 15 % of the plotting time at level 6; the files are 18 % larger
        fig.savefig(out_dir / name, dpi=90, pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
        written.append(name)
    return written


#: This process's figures by layout, reused from scenario to scenario (see :func:`_figure`).
_FIGURES: dict[tuple, tuple[Any, np.ndarray]] = {}


def _figure(key: tuple, nrows: int, ncols: int, figsize: tuple[float, float], margins: dict[str, float]):
    """The figure of layout ``key`` (``nrows`` x ``ncols`` axes sharing x), emptied of what
    the last scenario drew in it; made once per layout and process, since creating the
    axes and their ticks was 30 % of the plotting time.  Every draw sets the titles
    and labels again; a reused figure draws the same pixels as a new one
    (tests/scenarios/test_plots.py).  One scenario at a time: matplotlib is not thread-safe."""
    if key not in _FIGURES:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=figsize)
        FigureCanvasAgg(fig)
        axes = fig.subplots(nrows, ncols, sharex=True, squeeze=False)
        # fixed margins (figure fractions): tight_layout measured every text twice, a third of the time
        fig.subplots_adjust(**margins)
        _FIGURES[key] = (fig, axes)
        return fig, axes
    fig, axes = _FIGURES[key]
    for ax in axes.flat:
        for artist in [*ax.lines, *ax.collections, *ax.texts]:
            artist.remove()
        if ax.get_legend() is not None:
            ax.get_legend().remove()
        ax.relim()
    return fig, axes


def _velocity(scenario: Scenario, results: Sequence[Any], colors: list[str]):
    """Step-averaged (and, for vy, stride-averaged) velocity against the command; the
    yaw rate against its command when the scenario turns."""
    turns = any(c.yaw_rate_des for c in scenario.commands)
    fig, axes = _figure(("velocity", turns), 3 if turns else 2, 1, (10, 8.5 if turns else 6),
                        dict(left=0.08, right=0.98, bottom=0.09, top=0.94, hspace=0.08))
    axes = axes[:, 0]
    if turns:
        _yaw_rate(axes[2], results, colors)
    for ax, axis in zip(axes, ("vx", "vy")):
        for i, r in enumerate(results):
            c = colors[i % len(colors)]
            t = r.rows["t"]
            raw = f"tel_{axis}" if f"tel_{axis}" in r.rows.dtype.names else f"in_{axis}"
            ax.plot(t, r.rows[raw], color=c, alpha=0.25, lw=0.6)
            e = metrics.velocity_errors(r.rows)[0 if axis == "vx" else 1]
            ax.plot(t, e + r.rows[f"cmd_{axis}_des"], color=c, lw=1.4, label=f"{r.arm}: step average")
            if axis == "vy":  # the step average alternates with the sway; the stride does not
                ax.plot(t, metrics.lateral_stride_error(r.rows) + r.rows["cmd_vy_des"], color=c, lw=1.4,
                        ls="--", label=f"{r.arm}: stride (2-step) average")
            if r.fell:
                ax.axvline(r.t_fall_s, color=c, ls=":", lw=1)
        ax.plot(results[0].rows["t"], results[0].rows[f"cmd_{axis}_des"], "k--", lw=1.2, label="command")
        ax.set_ylabel(f"{axis} (m/s)")
        ax.grid(alpha=0.3)
    if scenario.perturbation_t_s > 0:
        for ax in axes:
            ax.axvline(scenario.perturbation_t_s, color="grey", ls="-.", lw=0.8)
    for ax in axes:
        ax.legend(loc="best", fontsize=8)
    axes[0].set_title(f"{scenario.name}: velocity vs command (faint: instantaneous)", y=TITLE_Y)
    axes[-1].set_xlabel("t (s)")
    return fig


def _yaw_rate(ax, results: Sequence[Any], colors: list[str]) -> None:
    """Yaw rate per arm (faint: instantaneous; bold: the heading's change over the last
    :data:`YAW_RATE_MEAN_S`) against the commanded yaw rate."""
    for i, r in enumerate(results):
        c, t = colors[i % len(colors)], r.rows["t"]
        ax.plot(t, r.rows["tel_yaw_rate"], color=c, alpha=0.25, lw=0.6)
        n = max(1, round(YAW_RATE_MEAN_S / metrics.comm_step(r.rows))) if len(t) > 1 else 0
        if 0 < n < len(t):
            yaw = np.unwrap(r.rows["tel_yaw"])
            ax.plot(t[n:], (yaw[n:] - yaw[:-n]) / (t[n:] - t[:-n]), color=c, lw=1.4,
                    label=f"{r.arm}: mean over {YAW_RATE_MEAN_S:g} s")
        if r.fell:
            ax.axvline(r.t_fall_s, color=c, ls=":", lw=1)
    ax.plot(results[0].rows["t"], results[0].rows["cmd_yaw_rate_des"], "k--", lw=1.2, label="command")
    ax.set_ylabel("yaw rate (rad/s)")
    ax.grid(alpha=0.3)


def _psi(scenario: Scenario, results: Sequence[Any], colors: list[str]):
    """The networks' outputs (Psi) and the joint offsets they produce, one panel each."""
    columns = {n for r in results for n in r.rows.dtype.names}  # the rl_hzd arm has no psi_*
    deltas = [n[4:] for n in results[0].rows.dtype.names if n.startswith("out_delta_")]
    psis = [n for n in PSI_NAMES if f"out_{n}" in columns]
    panels = psis + deltas
    ncols = 2
    nrows = max(1, (len(panels) + ncols - 1) // ncols)
    height = 2.0 * nrows + 0.8
    fig, axes = _figure(("psi", nrows, len(panels)), nrows, ncols, (11, height),
                        dict(left=0.075, right=0.985, bottom=0.8 / height, top=1 - 0.65 / height,
                             hspace=0.32, wspace=0.2))
    handles = {}  # one line per arm for the legend, from the first panel the arm has
    for idx, name in enumerate(panels):
        ax = axes[idx // ncols][idx % ncols]
        for i, r in enumerate(results):
            if f"out_{name}" in r.rows.dtype.names:
                (line,) = ax.plot(r.rows["t"], r.rows[f"out_{name}"], color=colors[i % len(colors)], lw=0.9)
                handles.setdefault(r.arm, line)
        ax.set_title(name + (" (rad)" if name.startswith("delta_") else ""), fontsize=9, y=TITLE_Y)
        ax.grid(alpha=0.3)
    for idx in range(len(panels), nrows * ncols):
        axes[idx // ncols][idx % ncols].axis("off")
    for ax in axes[-1]:
        ax.set_xlabel("t (s)")
    if handles:  # every arm in the scenario's order, also one without Psi outputs (rl_hzd)
        arms = [r.arm for r in results if r.arm in handles]
        axes[0][0].legend([handles[a] for a in arms], arms, fontsize=8)
    fig.suptitle(f"{scenario.name}: Psi outputs and joint offsets per arm")
    return fig


def _torso(scenario: Scenario, results: Sequence[Any], colors: list[str]):
    """Torso pitch and roll, degrees."""
    fig, axes = _figure(("torso",), 2, 1, (10, 5), dict(left=0.08, right=0.98, bottom=0.1, top=0.93, hspace=0.08))
    axes = axes[:, 0]
    for ax, name in zip(axes, ("pitch", "roll")):
        for i, r in enumerate(results):
            ax.plot(r.rows["t"], np.degrees(r.rows[f"in_{name}"]), color=colors[i % len(colors)], lw=0.9, label=r.arm)
        ax.set_ylabel(f"torso {name} (deg)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[0].set_title(f"{scenario.name}: torso angles", y=TITLE_Y)
    axes[-1].set_xlabel("t (s)")
    return fig
