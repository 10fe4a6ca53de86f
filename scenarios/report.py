"""``python -m scenarios report DIR``: one markdown page over every scenario's results.

For every scenario of the suite and every other result folder found in ``DIR``: the
table rows (one per arm), the plots, the paper's claim beside the measured numbers
and a pass/miss verdict per check with both sides' values. Nothing is hidden: a
scenario of the suite without results is listed as "not run", a failed or interrupted
run with why, an arm that fell with its fall time. Nothing is taken on trust either:
each summary.json is checked against the format this package writes
(:func:`scenarios.results.output.summary_problems`; one of another shape is listed as invalid,
naming the file and what is wrong) and every verdict is recomputed from the arms, a
pass only when every arm is complete.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from fmu_src.core.avr_errors import AvrError
from scenarios.lang.formatting import show
from scenarios.results.metrics import CONVERGENCE_TOL_MPS, LEVEL_WINDOW_S, STEADY_WINDOW_S
from scenarios.results.output import TABLE_COLUMNS, fmt, incomplete_arms, summary_commands, table_rows
from scenarios.results.output import verdict as output_verdict

#: Claim values in the report: 4 significant digits.
REPORT_FLOAT_FORMAT = ".4g"


def collect(out_dir: Path) -> list[tuple[str, dict[str, Any] | None, str | None]]:
    """(name, summary or None, problem) for the suite's scenarios and every result folder
    (a summary.json that is not what this package writes is a problem, never rendered)."""
    from scenarios.lang import spec
    from scenarios.results.store import read_summary

    found: dict[str, dict[str, Any] | None] = {}
    problems: dict[str, str] = {}
    for f in sorted(Path(out_dir).glob("*/summary.json")):
        name = f.parent.name
        if name.startswith("."):  # a run's scratch folder or lock (scenarios.results.store)
            continue
        found[name], bad = read_summary(f)
        if bad:
            problems[name] = f"invalid {f}: " + "; ".join(bad)
    suite = [p.stem for p in spec.suite_files()]  # a suite scenario's name is its file's stem
    order = suite + sorted(n for n in found if n not in suite)
    out = []
    for name in order:
        if name in found:
            out.append((name, found[name], problems.get(name)))
        else:
            out.append((name, None, "not run (no results in this folder)"))
    return out


def _why_incomplete(s: dict[str, Any]) -> str:
    return s.get("error") or "arms " + ", ".join(incomplete_arms(s))


def _md_escape(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _num(v: Any) -> str:
    return show(v, REPORT_FLOAT_FORMAT, none="null", quote=False)


def _turn(yaw_rate: float) -> str:
    return f", turning {yaw_rate:g} rad/s" if yaw_rate else ""


def _plant_line(s: dict[str, Any]) -> str:
    """Commands, perturbation as specified, and the plant as actually loaded (model summary)."""
    parts = []
    cmds = summary_commands(s)
    if cmds:
        parts.append("command " + ", ".join(f"({vx:g}, {vy:g}) m/s{_turn(yaw_rate)} from {t:g} s"
                                            for t, vx, vy, yaw_rate in cmds))
    p = s.get("perturbation") or {}
    if p.get("torso_mass_kg") is not None:
        parts.append(f"torso mass {p['torso_mass_kg']:g} kg")
    if p.get("torso_added_mass_kg"):
        parts.append(f"torso mass {p['torso_added_mass_kg']:+g} kg")
    if any(p.get("torso_com_offset_m") or []):
        parts.append("torso COM offset [" + ", ".join(f"{c:g}" for c in p["torso_com_offset_m"]) + "] m")
    if p.get("joint_damping_scale", 1.0) != 1.0:
        parts.append(f"joint damping x{p['joint_damping_scale']:g}")
    for push in p.get("pushes") or []:
        parts.append(f"push [{', '.join(f'{f:g}' for f in push['force_n'])}] N at {push['t_s']:g} s "
                     f"for {push['duration_s']:g} s")
    if p.get("terrain"):
        t = p["terrain"]
        parts.append(f"terrain heights <= {t['max_height_m']:g} m, slopes <= {t['max_slope_deg']:g} deg "
                     f"(seed {t['seed']})")
    ms = s.get("model_summary") or {}
    if ms.get("pelvis_mass_kg") is not None:
        com = ms.get("pelvis_com_m") or []
        parts.append(f"loaded plant: pelvis {ms['pelvis_mass_kg']:.2f} kg, pelvis COM ["
                     + ", ".join(f"{c:.3f}" for c in com) + f"] m, total {ms.get('total_mass_kg', 0):.2f} kg")
    return ("Setup: " + "; ".join(parts) + ".") if parts else ""


def render(out_dir: Path, entries: list | None = None) -> str:
    entries = collect(out_dir) if entries is None else entries
    lines = ["# Scenario report", ""]
    lines.append(f"Results folder: `{Path(out_dir)}`. One section per scenario; every arm is listed. "
                 "Velocity errors are of the step-averaged velocity against the command: `sse_v*` is the mean "
                 f"|error| over the last {STEADY_WINDOW_S:g} s, `sse_yaw` the |mean yaw rate - command| over the "
                 f"same window (rad/s), `t_conv_s` the time from `perturbation_t_s` after which both velocity "
                 f"errors stay within {CONVERGENCE_TOL_MPS:g} m/s (null if never, or if the robot fell).")
    lines.append("")
    lines += _overview(entries)
    for name, s, problem in entries:
        lines += _section(name, s, problem)
    return "\n".join(lines) + "\n"


def _overview(entries: list) -> list[str]:
    """One row per scenario (status, regulator, model, verdict) and the verdict counts."""
    counts = {"pass": 0, "miss": 0, "n/a": 0}
    lines = ["## Overview", "", "| scenario | status | regulator | model | verdict |", "|---|---|---|---|---|"]
    for name, s, problem in entries:
        if s is None:
            lines.append(f"| {name} | {_md_escape(problem)} | - | - | n/a |")
            counts["n/a"] += 1
            continue
        verdict = output_verdict(s)["overall"]
        counts[verdict] = counts.get(verdict, 0) + 1
        status = s["status"]
        if status != "complete":
            status = f"{status}: {_md_escape(_why_incomplete(s)[:120])}"
        lines.append(f"| [{name}](#{name}) | {status} | {s.get('regulator', '-')} | "
                     f"{_md_escape(Path(str(s.get('model', '-'))).name)} | **{verdict}** |")
    return lines + ["", f"Verdicts: {counts['pass']} pass, {counts['miss']} miss, {counts['n/a']} n/a "
                        "(not run, failed or no checks).", ""]


def _section(name: str, s: dict[str, Any] | None, problem: str | None) -> list[str]:
    """A scenario's section: set-up, plant, the arms' table, the claim and the plots."""
    lines = [f"## {name}", ""]
    if s is None:
        return lines + [f"**Not available:** {problem}.", ""]
    if s.get("description"):
        lines += [_md_escape(s["description"]), ""]
    lines.append(f"Model `{_md_escape(Path(str(s.get('model'))).name)}`, regulator `{s.get('regulator')}`, "
                 f"duration {s.get('duration_s')} s, comm step {s.get('comm_step_s')} s, seed {s.get('seed')}, "
                 f"perturbation from t = {s.get('perturbation_t_s')} s.")
    lines.append("")
    plant = _plant_line(s)
    if plant:
        lines += [plant, ""]
    if s["status"] != "complete":
        lines += [f"**Run {s['status']}:** `{_md_escape(_why_incomplete(s))}`", ""]
    if s.get("arm_names") or s.get("arms"):
        lines += _arm_table(s)
        lines += _level_table(s)
    lines += _claim(s)
    for plot in s.get("plots") or []:
        lines += [f"![{name} {plot}]({name}/{plot})", ""]
    videos = s.get("videos") or []
    if videos:  # run --render: the GIFs shown, the MP4s linked
        lines += ["Videos: " + ", ".join(f"[{v}]({name}/{v})" for v in videos if v.endswith(".mp4")), ""]
        lines += [f"![{name} {v}]({name}/{v})" for v in videos if v.endswith(".gif")] + [""]
    return lines


def _arm_table(s: dict[str, Any]) -> list[str]:
    header = [h for _, h, _ in TABLE_COLUMNS[1:]]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in table_rows(s):
        if row.get("status") != "complete":
            lines.append(f"| {row.get('arm')} | {row.get('status')} |" + " |" * (len(header) - 2))
            continue
        cells = [fmt(row.get(k), d) for k, _, d in TABLE_COLUMNS[1:]]
        if row.get("fell") and row.get("fall_reason"):
            cells[1] = f"yes ({_md_escape(row['fall_reason'])})"
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]


def _level_table(s: dict[str, Any]) -> list[str]:
    """Per command level (scenarios with more than one): each complete arm's
    ``level_errors_vx`` (mean |step-averaged forward error| over the level's last seconds)."""
    arms = {a: m for a, m in (s.get("arms") or {}).items()
            if m.get("status") == "complete" and m.get("level_errors_vx")}
    if not arms or max(len(m["level_errors_vx"]) for m in arms.values()) < 2:
        return []
    levels = max(arms.values(), key=lambda m: len(m["level_errors_vx"]))["level_errors_vx"]
    head = ["arm"] + [f"{show(lv['vx_des'])} m/s from {show(lv['t_s'])} s" for lv in levels]
    lines = [f"Forward error per command level (m/s, mean over each level's last "
             f"{show(LEVEL_WINDOW_S)} s; `-`: shorter than that, or the level the arm fell in):", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for arm, m in arms.items():
        cells = [fmt(lv.get("error_vx"), 3) for lv in m["level_errors_vx"]]
        lines.append("| " + " | ".join([arm] + cells + ["-"] * (len(levels) - len(cells))) + " |")
    return lines + [""]


def _claim(s: dict[str, Any]) -> list[str]:
    """The paper's claim, each check with both sides' values, and the verdict."""
    claim = s.get("claim")
    if not claim:
        return ["_No claim given for this scenario._", ""]
    lines = ["**Paper's claim:** " + _md_escape(claim.get("text", "")), ""]
    if claim.get("source"):
        lines += [f"_Source: {_md_escape(claim['source'])}_", ""]
    verdict = output_verdict(s)
    if verdict.get("why"):
        lines += [f"_No verdict: {_md_escape(verdict['why'])}._", ""]
    if verdict.get("checks"):
        lines += ["| check | measured | reference | verdict |", "|---|---|---|---|"]
        for c in verdict["checks"]:
            why = f" ({c['why']})" if c.get("why") else ""
            lines.append(f"| `{_md_escape(c['text'])}` | {_num(c.get('lhs'))} | {_num(c.get('rhs'))} | "
                         f"**{c['verdict']}**{why} |")
        lines.append("")
    return lines + [f"**Verdict: {verdict.get('overall', 'n/a')}**", ""]


def write_report(out_dir: Path) -> tuple[Path, list[str]]:
    """Write ``out_dir/report.md``; return its path and the invalid summaries (each
    naming its file and what is wrong; they are listed in the report, not rendered)."""
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        raise AvrError(f"no such results folder: {out_dir}")
    from scenarios.campaign.report import campaigns_section, is_campaign_dir, write_report as write_campaign

    if is_campaign_dir(out_dir):  # a campaign folder: its own campaign.md
        return write_campaign(out_dir), []
    entries = collect(out_dir)
    path = out_dir / "report.md"
    path.write_text(render(out_dir, entries) + campaigns_section(out_dir))
    return path, [p for name, s, p in entries if s is None and p and p.startswith("invalid ")]
