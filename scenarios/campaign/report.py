"""``DIR/campaign.md`` (with its plots) and the plain-text table the CLI prints.

``python -m scenarios report DIR`` writes it for a campaign folder, and lists the
campaign folders inside a results folder in ``report.md``.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Sequence

from scenarios.campaign import analysis
from scenarios.campaign.plots import PAIRED, write_plots
from scenarios.campaign.store import COPY_NAME, REPORT_NAME

log = logging.getLogger(__name__)

is_campaign_dir = analysis.is_campaign_dir

SSE = (("steady_state_error_vx", "sse_vx"), ("steady_state_error_vy", "sse_vy"))


def _f(v: Any, digits: int = 3) -> str:
    return "-" if v is None else f"{v:.{digits}f}" if isinstance(v, float) else str(v)


def _rate(s: dict[str, Any]) -> str:
    if s["fall_rate"] is None:
        return "-"
    lo, hi = s["fall_ci"]
    return f"{s['fell']}/{s['complete']} = {100 * s['fall_rate']:.0f} % [{100 * lo:.0f}, {100 * hi:.0f}]"


def stats_table(data: analysis.CampaignData) -> tuple[list[str], list[list[str]]]:
    header = ["arm", "complete", "failed", "fell (95 % CI)", "sse_vx p50", "sse_vx p90", "sse_vx max",
              "sse_vy p50", "sse_vy p90", "settled_vx p50", "settled_vx p90", "converged", "t_conv p50 (s)"]
    rows = []
    for arm in data.arms:
        s = analysis.arm_stats(data.rows, arm)
        cells = [arm, str(s["complete"]), str(s["failed"]), _rate(s)]
        for key, _ in SSE:
            q = s[key]
            cells += [_f(q["p50"]), _f(q["p90"])] + ([_f(q["max"])] if key.endswith("vx") else [])
        q = s["settled_error_vx"]
        cells += [_f(q["p50"]), _f(q["p90"])]
        cells += [f"{s['converged']}/{s['walked']}", _f(s["convergence_p50"], 1)]
        rows.append(cells)
    return header, rows


def text_table(data: analysis.CampaignData) -> str:
    header, rows = stats_table(data)
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(header)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths)), "  ".join("-" * w for w in widths)]
    return "\n".join(lines + ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows])


def _md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + \
        ["| " + " | ".join(str(c).replace("|", "\\|") for c in r) + " |" for r in rows]


def _factor_cells(r: dict[str, Any], factors: Sequence[str]) -> str:
    return ", ".join(f"{f} = {_f(r[f], 3) if isinstance(r[f], float) else r[f]}" for f in factors)


def _paired_lines(data: analysis.CampaignData, plot: bool) -> list[str]:
    if len(data.arms) < 2:
        return []
    a, b = data.arms[:2]
    p = analysis.paired(data.rows, a, b)
    lines = [f"## {a} vs {b}, sample by sample", "",
             f"{p['n']} samples with both arms complete (same plant, command and seed). Both fell: "
             f"{p['both_fell']}; only {a} fell: {len(p['only_a_fell'])}; only {b} fell: {len(p['only_b_fell'])}. "
             f"Both kept walking: {p['both_walked']}; {a} had the lower sse_vx in {p['a_lower_vx']} of them "
             f"(median difference {a} - {b}: {_f(p['median_diff_vx'], 4)} m/s) and the lower sse_vy in "
             f"{p['a_lower_vy']} (median difference {_f(p['median_diff_vy'], 4)} m/s, largest "
             f"{_f(p['max_diff_vy'], 4)} m/s).", ""]
    lines += _verdict_lines(data, a, b)
    lines += _agreement_lines(data, b)
    return lines + ([f"![paired]({PAIRED})", ""] if plot else [])


def _pct(ci) -> str:
    return "-" if ci is None else f"[{100 * ci[0]:.1f}, {100 * ci[1]:.1f}] %"


#: Short names of the errors the verdicts may compare.
METRIC_LABEL = {"steady_state_error_vx": "sse_vx (the last 5 s)",
                "settled_error_vx": "settled_vx (every row where the command has been constant for 2.5 s, after 5 s)"}


def _verdict_lines(data: analysis.CampaignData, a: str, b: str) -> list[str]:
    """The paired claims as explicit verdicts (:func:`scenarios.campaign.analysis.verdicts`),
    and every sample the first arm does not win."""
    metric = data.metric
    ra, rb = data.replicas(a), data.replicas(b)
    vrows = data.verdict_rows()
    v = analysis.verdicts(vrows, a, b, metric=metric, replicas_a=ra, replicas_b=rb)
    n_rep = v["replicas"]
    fell = ", ".join(f"[{s}](samples/{s}.toml)" for s in v["only_a_fell"]) or "none"
    some = ", ".join(f"{s} ({k}/{n_rep})" for s, k in v["a_fell_some"]) or "none"
    share = "-" if v["win_share"] is None else f"{100 * v['win_share']:.1f} %"
    ci = v["median_diff_ci"]
    label = METRIC_LABEL.get(metric, metric)
    lines = []
    over = data.replicate_over
    if n_rep > 1 and over:
        redrawn = ", ".join(f"`{n}`" for n in over.get("redraw") or ())
        anew = f" with its own draw of {redrawn} on each value" if redrawn else ""
        lines += [f"Each random draw runs on the {n_rep} values of the grid factor `{over['factor']}`{anew}, {a} and "
                  f"{b} paired on each value; below a sample names the draw by its sample on the first value "
                  f"({a}@k, {b}@k: the arm on value k). Near the edge of falling any change of the walk tips a "
                  f"run into a fall or out of one, so the verdicts judge each draw by its outcomes over the "
                  f"{n_rep} values.", ""]
    elif n_rep > 1:
        lines += [f"Each sample runs {a} and {b} {n_rep} times each, paired by position: "
                  f"{', '.join([a, *ra])} against {', '.join([b, *rb])}. Near the edge of falling any change of "
                  "the walk tips a sample into a fall or out of one, so the verdicts judge each sample by its "
                  f"outcomes over the {n_rep} pairs.", ""]
    runs = (data.manifest.get("confirm_runs") or 0) if n_rep > 1 else 0  # confirm_runs needs replicate_over
    ok = v["never_falls_where_b_walks"]
    head = (f"Screen of the majority reading: {'no draw listed' if ok else 'draws listed'}" if runs else
            f"**Verdict: {a} never falls where {b} walks: {'PASS' if ok else 'FAIL'}**")
    if n_rep > 1:
        never = (f"{head}"
                 f" (samples where {a} fell on more than half of the {n_rep} replicas and {b} on fewer than half: "
                 f"{len(v['only_a_fell'])} of {v['n']}, exact 95 % interval {_pct(v['only_a_fell_ci'])}; {fell}. "
                 f"Samples where {a} fell on some replica and {b} on none, with {a}'s falls: {some}).")
        win = (f"a pair is won when only {b} fell, or both walked and {a}'s {label} is lower; a sample is won "
               "with more than half of its pairs where at least one arm walked")
    else:
        never = (f"{head}"
                 f" ({len(v['only_a_fell'])} of {v['n']} paired samples, exact 95 % interval "
                 f"{_pct(v['only_a_fell_ci'])}; samples: {fell}).")
        win = f"a win: only {b} fell, or both walked and {a}'s {label} is lower"
    null = v.get("only_a_fell_null")
    if null is not None:
        never += (f" Chance level: with the two runs of each pair swapped at random ({analysis.SWAPS_N} times), "
                  f"as if either arm were as likely to be the one that falls, the same reading lists "
                  f"{null['mean']:.1f} samples on average (95 %: {null['low']:.0f}-{null['high']:.0f}), and "
                  f"{len(v['only_a_fell'])} or more in {100 * null['at_least_observed']:.0f} % of the swaps.")
    lines += [never, ""] + (_confirm_lines(data, a, b, v["only_a_fell"], runs) if runs else [])
    lines += [f"**Verdict: {a} beats {b} on >= {100 * analysis.WIN_SHARE_REQUIRED:.0f} % of paired samples: "
              f"{'PASS' if v['beats'] else 'FAIL'}** ({v['wins']} of {v['contested']} samples where at least one arm "
              f"walked = {share}, exact 95 % interval {_pct(v['win_ci'])}; {win}). Median {metric} difference "
              f"{a} - {b} over the pairs both walked: {_f(v['median_diff'], 4)} m/s (bootstrap 95 % interval "
              f"{'-' if ci is None else f'[{ci[0]:.4f}, {ci[1]:.4f}]'} m/s).", ""]
    if v["not_won"]:
        by = {(r["sample"], r["arm"]): r for r in vrows if r["status"] == "complete"}

        def mean_error(s: str, arms: Sequence[str]) -> str:
            vals = [by[(s, x)][metric] for x in arms if not by[(s, x)]["fell"] and by[(s, x)][metric] is not None]
            return _f(sum(vals) / len(vals)) if vals else "-"

        rows = [[f"[{s}](samples/{s}.toml)", f"{won}/{contested}", f"{fa}/{n_rep}", f"{fb}/{n_rep}",
                 mean_error(s, [a, *ra]), mean_error(s, [b, *rb]), _factor_cells(by[(s, a)], data.factors)]
                for s, won, contested, fa, fb in v["not_won"]]
        lines += [f"Every sample {a} does not win ({len(v['not_won'])}):", ""]
        lines += _md_table(["sample", "pairs won", f"{a} fell", f"{b} fell", f"{a} {metric} (mean of walked)",
                            f"{b} {metric}", "factors"], rows) + [""]
    return lines


def _confirm_lines(data: analysis.CampaignData, a: str, b: str, listed: Sequence[str], runs: int) -> list[str]:
    """The verdict "``a`` never falls where ``b`` walks" after the confirmation stage
    (:func:`scenarios.campaign.analysis.confirmation`), with every listed draw's fresh runs."""
    head = f"**Verdict: {a} never falls where {b} walks, confirmed on {runs} fresh runs of each listed draw: "
    alpha = analysis.CONFIRM_ALPHA
    test = (f"a listed draw is confirmed when its fresh runs where only {a} fell outnumber those where only {b} "
            f"fell beyond chance: one-sided exact McNemar test, Holm's step-down over the listed draws at "
            f"{alpha:g}; only fresh runs count, as the runs that listed a draw were selected for going against {a}")
    if not listed:
        return [head + f"PASS** (the screen lists no draw; {test}).", ""]
    stage = analysis.load_confirmation(data.root)
    of = (stage.manifest.get("confirm_of") or {}) if stage is not None else {}
    c = analysis.confirmation(listed, stage.rows if stage is not None else [], of, a, b, runs)
    verdict = "FAIL" if c["confirmed"] else "PASS" if c["complete"] else "INCOMPLETE"
    done = sum(x["runs"] for x in c["draws"])
    status = "" if c["complete"] else (f" The stage is not complete: {done} of {runs * len(listed)} fresh pairs "
                                       f"({'none run' if stage is None else f'in {stage.root}'}).")
    confirmed = ", ".join(c["confirmed"]) or "none"
    rows = [[x["draw"], f"{x['runs']}/{runs}", f"{x['a_fell']}", f"{x['b_fell']}", f"{x['only_a']}",
             f"{x['only_b']}", f"{x['p']:.3g}", "yes" if x["confirmed"] else "no"] for x in c["draws"]]
    return ([head + f"{verdict}** (confirmed: {confirmed}; {test}).{status}", ""]
            + _md_table(["draw", "fresh pairs", f"{a} fell", f"{b} fell", f"only {a} fell", f"only {b} fell",
                         "one-sided p", "confirmed"], rows) + [""])


def _agreement_lines(data: analysis.CampaignData, b: str) -> list[str]:
    """Every other arm against ``b``, on falls only (:func:`scenarios.campaign.analysis.fall_agreement`)."""
    if len(data.arms) < 3:
        return []
    rows = []
    for g in analysis.fall_agreement(data.rows, b, data.arms):
        p = g["p_value"]
        rows.append([g["arm"], str(g["n"]), str(len(g["only_arm_fell"])), str(len(g["only_b_fell"])),
                     "-" if p is None else f"{p:.3g}",
                     ", ".join(g["only_arm_fell"]) or "none"])
    return ([f"Falls of every arm against {b} on the same samples (two-sided exact McNemar test of the "
             f"split; an arm that differs from {b} by a small change of one gain shows how many such "
             "samples chance alone gives):", ""]
            + _md_table(["arm", "paired", f"fell where {b} walked", f"{b} fell where it walked", "McNemar p",
                         f"samples where it fell and {b} walked"], rows) + [""]
            + _never_reading_lines(data, b))


def _never_reading_lines(data: analysis.CampaignData, b: str) -> list[str]:
    """The "never falls where ``b`` walks" reading of the verdicts, for every other arm with
    as many replicas as ``b`` (with ``replicate_over``, every arm): an arm that differs from
    ``b`` by a small change of one gain measures the count two equally robust controllers give,
    beside the swap model of it."""
    n_rep = len(data.replicas(b)) + 1
    if n_rep == 1:
        return []
    vrows = data.verdict_rows()
    rows = []
    for arm in data.arms:
        if arm == b or len(data.replicas(arm)) != n_rep - 1:
            continue
        v = analysis.verdicts(vrows, arm, b, metric=data.metric, replicas_a=data.replicas(arm),
                              replicas_b=data.replicas(b))
        null = v["only_a_fell_null"]
        chance = "-" if null is None else (f"{null['mean']:.1f} ({null['low']:.0f}-{null['high']:.0f}); "
                                           f"{100 * null['at_least_observed']:.0f} %")
        rows.append([arm, str(v["n"]), str(len(v["only_a_fell"])), chance, ", ".join(v["only_a_fell"]) or "none"])
    if not rows:
        return []
    return ([f"The \"never falls where {b} walks\" reading for every arm against {b}: samples where the arm fell "
             f"on more than half of the {n_rep} replicas and {b} on fewer than half, with the chance level of "
             f"the verdict (mean count over the swaps, its 95 % range; the share of swaps listing as many). "
             f"An arm that differs from {b} by a small change of one gain measures the count two equally robust "
             "controllers give:", ""]
            + _md_table(["arm", "samples", "listed", "chance level; swaps with as many", "listed samples"], rows)
            + [""])


def _worst_lines(data: analysis.CampaignData) -> list[str]:
    lines = ["## Worst samples per arm", "", "Falls first (earliest first), then the largest sse_vx. "
             "Re-run one alone: `python -m scenarios run samples/<id>.toml --out <folder>`.", ""]
    for arm in data.arms:
        rows = []
        for r in analysis.worst(data.rows, arm):
            outcome = f"fell at {r['t_fall_s']:.2f} s" if r["fell"] else f"sse_vx {_f(r['steady_state_error_vx'])}"
            run = f"[run]({r['run_dir']}/summary.json)" if r.get("run_dir") else "-"
            rows.append([f"[{r['sample']}](samples/{r['sample']}.toml)", outcome, run, _factor_cells(r, data.factors)])
        lines += [f"**{arm}**", ""] + _md_table(["sample", "outcome", "output", "factors"], rows) + [""]
    return lines


def _unconverged_lines(data: analysis.CampaignData) -> list[str]:
    """Per arm, the runs that kept walking but never settled within the convergence band."""
    lines = []
    for arm in data.arms:
        ids = [r["sample"] for r in data.rows if r["arm"] == arm and r["status"] == "complete"
               and r["fell"] is False and r["convergence_time_s"] is None]
        if ids:
            shown = ", ".join(f"[{i}](samples/{i}.toml)" for i in ids[:20]) + (" ..." if len(ids) > 20 else "")
            lines.append(f"- {arm}: kept walking but did not converge in {len(ids)} run(s): {shown}")
    return lines + [""] if lines else []


def render(data: analysis.CampaignData, plots: Sequence[str]) -> str:
    """campaign.md's text; ``plots``: the plots written beside it (``paired.png`` goes with its section)."""
    m = data.manifest
    failed = [r for r in data.rows if r["status"] != "complete"]
    expected = data.expected_rows
    drawn = f" (drawn from seed {m['seed']})" if "seed" in m else ""
    lines = [f"# Campaign {m['name']}", "",
             f"{m['n_samples']} samples{drawn} x {len(data.arms)} arms ({', '.join(data.arms)}); {len(data.rows)} of "
             f"{expected} rows present, {len(failed)} failed. Factors: {', '.join(data.factors)}. "
             f"Definition: [{COPY_NAME}]({COPY_NAME}); every sample's scenario: `samples/<id>.toml`; "
             "all rows: `campaign.csv`.", "",
             "Fall rate over the complete runs, with its 95 % Wilson interval; the velocity errors (`sse_*`: mean "
             "|step-averaged velocity - command| over the last 5 s, m/s; `settled_vx`: the same forward error over "
             "every row where the command has been constant for 2.5 s, after the first 5 s) and convergence over "
             "the runs that kept walking.", ""]
    lines += _md_table(*stats_table(data)) + [""]
    if len(data.rows) < expected:
        lines += [f"**Incomplete:** {expected - len(data.rows)} row(s) missing "
                  "(interrupted; `python -m scenarios campaign FILE --out DIR --resume` continues).", ""]
    for r in failed[:20]:
        lines.append(f"- failed: {r['sample']} / {r['arm']}: `{str(r.get('error') or '')[:200]}`")
    lines += [""] if failed else []
    lines += _unconverged_lines(data)
    lines += [f"![{p}]({p})" for p in plots if p != PAIRED] + [""]
    return "\n".join(lines + _paired_lines(data, PAIRED in plots) + _worst_lines(data)) + "\n"


def write_report(root: Path, *, plots: bool = True) -> Path:
    """Write ``root/campaign.md`` and (unless ``plots`` is false) its plots; return the path."""
    data = analysis.load(root)
    written = write_plots(data) if plots else []
    path = Path(root) / REPORT_NAME
    path.write_text(render(data, written))
    return path


def campaigns_section(out_dir: Path) -> str:
    """A section of report.md listing the campaign folders directly inside ``out_dir``."""
    dirs = sorted(p.parent for p in Path(out_dir).glob("*/campaign.json"))
    if not dirs:
        return ""
    lines = ["## Campaigns", ""]
    for d in dirs:
        try:
            write_report(d)
            header, rows = stats_table(analysis.load(d))
        except (OSError, ValueError, KeyError) as exc:
            lines += [f"### {d.name}", "", f"**Unreadable campaign folder:** {exc}", ""]
            continue
        lines += [f"### [{d.name}]({d.name}/{REPORT_NAME})", ""] + _md_table(header, rows) + [""]
    return "\n".join(lines) + "\n"
