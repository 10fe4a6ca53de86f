"""Writing one scenario's results: ``timeseries.csv``, ``summary.json`` and PNG plots.

``DIR/<name>/timeseries.csv``: every arm's rows, the ``arm`` column first.
``DIR/<name>/summary.json``: ``scenario``, ``model``, ``regulator``, the claim and its
evaluated checks, and per arm the metrics of :mod:`scenarios.metrics`.
``DIR/<name>/velocity.png``, ``psi.png``, ``torso.png``: matplotlib (Agg) plots.
A failed run writes ``summary.json`` with ``status = "error"`` and the message (and the
arms that did finish), so the report lists it instead of hiding it.
"""
from __future__ import annotations

import io
import json
import logging
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from scenarios import metrics
from scenarios.spec import Scenario

log = logging.getLogger(__name__)

PLOTS = ("velocity.png", "psi.png", "torso.png")
PSI_NAMES = ("psi_x", "psi_y", "psi_pitch", "psi_roll")


def claim_dict(scenario: Scenario) -> dict[str, Any] | None:
    if scenario.claim is None:
        return None
    return {
        "text": scenario.claim.text,
        "source": scenario.claim.source,
        "checks": [
            {"arm": c.arm, "metric": c.metric, "op": c.op, "value": c.value, "other_arm": c.other_arm}
            for c in scenario.claim.checks
        ],
    }


def scenario_header(scenario: Scenario, regulator: str) -> dict[str, Any]:
    return {
        "scenario": scenario.name,
        "description": scenario.description,
        "source": scenario.source,
        "tags": list(scenario.tags),
        "model": scenario.model,
        "regulator": regulator,
        "duration_s": scenario.duration_s,
        "comm_step_s": scenario.comm_step_s,
        "seed": scenario.seed,
        "perturbation_t_s": scenario.perturbation_t_s,
        "arm_names": [a.name for a in scenario.arms],
        "commands": [[c.t_s, c.vx_des, c.vy_des] for c in scenario.commands],
        "perturbation": {
            "torso_mass_kg": scenario.torso_mass_kg,
            "torso_added_mass_kg": scenario.torso_added_mass_kg,
            "torso_com_offset_m": list(scenario.torso_com_offset_m),
            "joint_damping_scale": scenario.joint_damping_scale,
            "pushes": [{"t_s": p.t_s, "force_n": list(p.force_n), "duration_s": p.duration_s}
                       for p in scenario.pushes],
            "terrain": None if scenario.terrain is None else {
                "max_height_m": scenario.terrain.max_height_m, "max_slope_deg": scenario.terrain.max_slope_deg,
                "seed": scenario.terrain.seed, "size_m": scenario.terrain.size_m},
        },
        "claim": claim_dict(scenario),
    }


def build_summary(scenario: Scenario, regulator: str, results: Sequence[Any]) -> dict[str, Any]:
    """summary.json content for the results (``master.ArmResult``) of one scenario."""
    out = scenario_header(scenario, regulator)
    arms: dict[str, Any] = {}
    for r in results:
        m = metrics.summarize_arm(r.rows, fell=r.fell, t_fall_s=r.t_fall_s,
                                  perturbation_t_s=scenario.perturbation_t_s, wall_s=r.wall_s)
        arm = scenario.arm(r.arm)
        m["fall_reason"] = r.fall_reason
        m["description"] = arm.description
        m["overrides"] = {k: v for k, v in arm.overrides}
        arms[r.arm] = m
    out["status"] = "ok"
    out["error"] = None
    out["arms"] = arms
    out["model_summary"] = results[0].model_summary if results else {}
    out["verdict"] = evaluate_claim(out["claim"], arms)
    return out


def evaluate_claim(claim: dict[str, Any] | None, arms: dict[str, Any]) -> dict[str, Any]:
    if not claim or not claim.get("checks"):
        return {"overall": "n/a", "checks": []}
    checks = [metrics.evaluate_check(c, arms) for c in claim["checks"]]
    overall = "pass" if all(c["verdict"] == "pass" for c in checks) else "miss"
    return {"overall": overall, "checks": checks}


def write_json(path: Path, data: dict[str, Any]) -> None:
    path.write_text(json.dumps(data, indent=2, sort_keys=False, default=_json_default) + "\n")


def _json_default(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"not JSON serializable: {type(o).__name__}")


def write_timeseries(path: Path, results: Sequence[Any]) -> None:
    """All arms in one CSV; the first column is ``arm``; floats round-trip exactly."""
    results = [r for r in results if len(r.rows)]
    with open(path, "w", newline="") as fh:
        if not results:
            fh.write("arm\n")
            return
        names = results[0].rows.dtype.names
        fh.write("arm," + ",".join(names) + "\n")
        for r in results:
            if r.rows.dtype.names != names:
                raise ValueError(f"arm {r.arm}: columns differ from arm {results[0].arm}")
            # Python floats' repr: the shortest text that reads back to the same double
            fmts = ["%d" if r.rows.dtype[n].kind in "iu" else "%r" for n in names]
            buf = io.StringIO()
            cols = [r.rows[n] for n in names]
            table = np.empty((len(r.rows), len(names)), dtype=object)
            for j, c in enumerate(cols):
                table[:, j] = c.tolist()
            np.savetxt(buf, table, fmt=fmts, delimiter=",")
            prefix = r.arm + ","
            fh.writelines(prefix + line + "\n" for line in buf.getvalue().splitlines())


def write_plots(out_dir: Path, scenario: Scenario, results: Sequence[Any]) -> list[str]:
    """velocity.png (velocity vs command per arm), psi.png (Psi and joint offsets), torso.png."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    results = [r for r in results if len(r.rows)]
    if not results:
        return []
    written = []

    def save(name: str, fig) -> str:
        fig.tight_layout()
        fig.savefig(out_dir / name, dpi=90)
        plt.close(fig)
        return name
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]

    # -- velocity vs command
    fig, axes = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    for ax, axis in zip(axes, ("vx", "vy")):
        ex, ey = None, None
        for i, r in enumerate(results):
            c = colors[i % len(colors)]
            t = r.rows["t"]
            raw = f"tel_{axis}" if f"tel_{axis}" in r.rows.dtype.names else f"in_{axis}"
            ax.plot(t, r.rows[raw], color=c, alpha=0.25, lw=0.6)
            e = metrics.velocity_errors(r.rows)[0 if axis == "vx" else 1]
            ax.plot(t, e + r.rows[f"cmd_{axis}_des"], color=c, lw=1.4, label=f"{r.arm}: step average")
            if r.fell:
                ax.axvline(r.t_fall_s, color=c, ls=":", lw=1)
        ax.plot(results[0].rows["t"], results[0].rows[f"cmd_{axis}_des"], "k--", lw=1.2, label="command")
        ax.set_ylabel(f"{axis} (m/s)")
        ax.grid(alpha=0.3)
    if scenario.perturbation_t_s > 0:
        for ax in axes:
            ax.axvline(scenario.perturbation_t_s, color="grey", ls="-.", lw=0.8)
    axes[0].legend(loc="best", fontsize=8)
    axes[0].set_title(f"{scenario.name}: velocity vs command (faint: instantaneous)")
    axes[-1].set_xlabel("t (s)")
    written.append(save("velocity.png", fig))

    # -- Psi (network outputs) and the joint offsets they produce
    deltas = [n[4:] for n in results[0].rows.dtype.names if n.startswith("out_delta_")]
    psis = [n for n in PSI_NAMES if f"out_{n}" in results[0].rows.dtype.names]
    panels = psis + deltas
    ncols = 2
    nrows = max(1, (len(panels) + ncols - 1) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(11, 2.0 * nrows + 0.8), sharex=True, squeeze=False)
    for idx, name in enumerate(panels):
        ax = axes[idx // ncols][idx % ncols]
        for i, r in enumerate(results):
            ax.plot(r.rows["t"], r.rows[f"out_{name}"], color=colors[i % len(colors)], lw=0.9, label=r.arm)
        ax.set_title(name + (" (rad)" if name.startswith("delta_") else ""), fontsize=9)
        ax.grid(alpha=0.3)
    for idx in range(len(panels), nrows * ncols):
        axes[idx // ncols][idx % ncols].axis("off")
    for ax in axes[-1]:
        ax.set_xlabel("t (s)")
    if panels:
        axes[0][0].legend(fontsize=8)
    fig.suptitle(f"{scenario.name}: Psi outputs and joint offsets per arm")
    written.append(save("psi.png", fig))

    # -- torso angles
    fig, axes = plt.subplots(2, 1, figsize=(10, 5), sharex=True)
    for ax, name in zip(axes, ("pitch", "roll")):
        for i, r in enumerate(results):
            ax.plot(r.rows["t"], np.degrees(r.rows[f"in_{name}"]), color=colors[i % len(colors)], lw=0.9, label=r.arm)
        ax.set_ylabel(f"torso {name} (deg)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[0].set_title(f"{scenario.name}: torso angles")
    axes[-1].set_xlabel("t (s)")
    written.append(save("torso.png", fig))
    return written


def write_results(out_root: Path, scenario: Scenario, regulator: str, results: Sequence[Any],
                  error: str | None = None) -> dict[str, Any]:
    """Write csv, summary and plots into ``out_root/<name>/``; return the summary.

    ``error`` marks the run failed (an arm raised): the arms that finished are still
    written, the others are listed as failed.
    """
    d = Path(out_root) / scenario.name
    d.mkdir(parents=True, exist_ok=True)
    summary = build_summary(scenario, regulator, results)
    if error is not None:
        summary["status"] = "error"
        summary["error"] = error
        summary["verdict"]["overall"] = "n/a"
    write_timeseries(d / "timeseries.csv", results)
    summary["plots"] = write_plots(d, scenario, results)
    write_json(d / "summary.json", summary)
    return summary


def table_rows(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per arm for the CLI and report; an arm without results says why.

    A scenario whose run failed before any arm finished gives one row (arm ``-``).
    """
    arms = summary.get("arms") or {}
    names = list(summary.get("arm_names") or arms)
    status = summary.get("status", "missing")
    if not names:
        return [{"scenario": summary.get("scenario"), "arm": "-", "status": status, "error": summary.get("error")}]
    rows = []
    for arm_name in names:
        m = arms.get(arm_name)
        if m is None:
            rows.append({"scenario": summary.get("scenario"), "arm": arm_name,
                         "status": "failed" if status == "error" else "missing", "error": summary.get("error")})
        else:
            rows.append({"scenario": summary.get("scenario"), "arm": arm_name, "status": "ok", **m})
    return rows


def fmt(v: Any, digits: int = 3) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.{digits}f}"
    return str(v)


#: (summary key, column header, decimals) of the table printed by the CLI and the report.
TABLE_COLUMNS = (
    ("scenario", "scenario", 0), ("arm", "arm", 0), ("fell", "fell", 0), ("t_fall_s", "t_fall_s", 2),
    ("steady_state_error_vx", "sse_vx", 3), ("steady_state_error_vy", "sse_vy", 3),
    ("convergence_time_s", "t_conv_s", 2), ("wall_s", "wall_s", 1), ("realtime_factor", "rtf", 2),
)


def format_table(summaries: Sequence[dict[str, Any]]) -> str:
    """A plain-text table, one row per scenario x arm (failed arms and scenarios say so)."""
    header = [h for _, h, _ in TABLE_COLUMNS] + ["verdict"]
    lines = []
    for s in summaries:
        verdict = (s.get("verdict") or {}).get("overall", "n/a")
        for row in table_rows(s):
            if row.get("status") != "ok":
                cells = [fmt(row.get("scenario")), fmt(row.get("arm"))] + [""] * (len(TABLE_COLUMNS) - 2)
                cells[2] = f"{row.get('status')}: {str(row.get('error') or '')[:60]}"
                lines.append(cells + [verdict])
                continue
            lines.append([fmt(row.get(k), d) for k, _, d in TABLE_COLUMNS] + [verdict])
    widths = [max([len(header[i])] + [len(line[i]) for line in lines]) for i in range(len(header))]
    out = ["  ".join(h.ljust(w) for h, w in zip(header, widths)), "  ".join("-" * w for w in widths)]
    out += ["  ".join(c.ljust(w) for c, w in zip(line, widths)).rstrip() for line in lines]
    return "\n".join(out)
