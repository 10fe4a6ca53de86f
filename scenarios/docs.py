"""``python -m scenarios docs``: the results tables of README.md and docs/, generated from committed data.

The data (``docs/data/``), each file written by a command, never typed into a page:

- ``suite.json``: every suite arm's metrics and every claim's verdict from one main-job run
  (``python -m scenarios docs --record-suite runs`` after ``python -m scenarios run all --out runs``),
  with the commit, machine and date it was measured on;
- ``robustness_study.csv``: the randomized-robots study, one row per campaign design x set x arm
  (falls, the "never" reading and its chance level, "beats" with its exact interval, the median
  settled errors, the commit that recorded it); ``robustness_confirm.csv``: the confirmation stage's
  robots on fresh runs.

A generated table sits in a page between ``<!-- table: NAME -->`` and ``<!-- /table -->``;
``python -m scenarios docs`` rewrites every such block from the data, ``--check`` lists every block
that differs (exit 1) and changes nothing (``tests/docs/test_docs_tables.py`` runs it).
"""
from __future__ import annotations

import csv
import datetime
import json
import platform
import re
import subprocess
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from fmu_src.core.avr_errors import AvrError

REPO_ROOT = Path(__file__).resolve().parent.parent
DATA_REL = Path("docs") / "data"
DATA_DIR = REPO_ROOT / DATA_REL
SUITE_DATA = DATA_DIR / "suite.json"
STUDY_DATA = DATA_DIR / "robustness_study.csv"
CONFIRM_DATA = DATA_DIR / "robustness_confirm.csv"
#: The benchmarks' numbers: ``<name>.json``, by the command that writes it (with ``--json FILE``).
BENCH_REL = DATA_REL / "benchmarks"
BENCHMARKS = {"suite": "python benchmarks/bench_suite.py",
              "suite_no_plots": "python benchmarks/bench_suite.py --no-plots",
              "cosim": "python benchmarks/bench_cosim.py",
              "campaign": "python benchmarks/bench_campaign.py --samples 100"}
#: The benchmarks' targets (issue 45), which the scripts print and the tables show: the main job's
#: fraction of the physics limit; our master's rate over the plain C host's on the same FMUs; a
#: campaign worker's rate over bare ``mj_step``, and the campaign's scaling from 1 to 2 workers.
BENCH_TARGETS = {"suite": 0.85, "master_over_c_host": 0.9, "campaign_rate": 0.8, "campaign_scaling": 1.8}
#: Every page that may hold generated tables.
PAGES = ("README.md", "docs/results.md", "docs/benchmarks.md")
#: The arm metrics recorded per suite arm (times of the run itself, ``wall_s`` and the like, are not results).
SUITE_METRICS = ("fell", "t_fall_s", "steady_state_error_vx", "steady_state_error_vy",
                 "steady_state_error_vy_stride", "steady_state_error_yaw_rate", "run_error_vx",
                 "settled_error_vx", "level_errors_vx", "convergence_time_s", "mean_vx_last_s",
                 "mean_vy_last_s", "max_abs_pitch_rad", "max_abs_roll_rad", "sim_s")
#: The README's headline rows: scenario and the perturbation it applies, in the paper's order.
HEADLINE = (
    ("nominal", "none, 0.5 m/s"),
    ("mass_20kg", "torso 20 kg (nominal 10.33 kg)"),
    ("com_fwd_10cm", "torso COM +0.1 m"),
    ("damping_x10", "joint damping x10"),
    ("push_fwd_30n", "30 N forward push for 0.1 s"),
    ("fast_mass_20kg", "20 kg, 1.2 m/s"),
    ("turning_mass_20kg", "20 kg, 0.3 rad/s turn"),
    ("compare_staircase_rl", "+5 kg, COM +0.1 m, 0.2-0.8 m/s"),
    ("terrain_mass_com", "+5 kg, COM +0.1 m, uneven terrain"),
)
#: The study's designs that ship (``scenarios/campaigns/robustness_random.toml``'s variants) and what each is.
SHIPPED_DESIGNS = (
    ("ramp", "adaptive, the `robust` settings (learning on settled commands and slow ramps, lr 2e-6)"),
    ("control", "PD-only with `Kp_x` 5 % up (a control arm: the readings' noise floor)"),
)
BEGIN = re.compile(r"<!-- table: ([a-z_]+) -->\n")
END = "<!-- /table -->"


class DocsError(AvrError):
    """The data or a page cannot give the tables (a missing file, a block without its end)."""


# --------------------------------------------------------------------------- recording
def _git_commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO_ROOT, capture_output=True,
                             text=True, check=True, timeout=30)
        return out.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def suite_data(run_dir: Path) -> dict[str, Any]:
    """The suite's results in ``run_dir`` as :data:`SUITE_DATA` holds them; every scenario of the
    suite must be there, complete, or this raises naming each that is not."""
    from scenarios.lang import spec
    from scenarios.results.store import read_summary

    scenarios: dict[str, Any] = {}
    problems = []
    for s in spec.load_suite(check_plant=False):
        path = Path(run_dir) / s.name / "summary.json"
        if not path.is_file():
            problems.append(f"{path}: missing (run the whole suite into {run_dir})")
            continue
        summary, bad = read_summary(path)
        if bad or summary is None:
            problems.append(f"{path}: " + "; ".join(bad))
            continue
        if summary["status"] != "complete":
            problems.append(f"{path}: status {summary['status']!r}, not complete")
            continue
        scenarios[s.name] = {
            "path": {k: summary["path"][k] for k in ("regulator", "plant", "controller")},
            "arms": {arm: {m: a.get(m) for m in SUITE_METRICS} for arm, a in summary["arms"].items()},
            "verdict": summary["verdict"]["overall"],
        }
    if problems:
        raise DocsError("cannot record the suite:\n  " + "\n  ".join(problems))
    return {"measured": measured_here(), "scenarios": scenarios}


def measured_here() -> dict[str, str]:
    """The commit, today's date and this machine, as the data files record them."""
    return {"commit": _git_commit(), "date": datetime.date.today().isoformat(),
            "machine": f"{_cpu_name()}, {platform.system()} {platform.machine()}"}


def record_suite(run_dir: Path, dest: Path | None = None) -> Path:
    data = suite_data(run_dir)
    dest = SUITE_DATA if dest is None else dest
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = dest.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    tmp.replace(dest)
    return dest


# --------------------------------------------------------------------------- reading
def load_suite(path: Path = SUITE_DATA) -> dict[str, Any]:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise DocsError(f"{path}: cannot read the suite data ({exc}); record it with "
                        "python -m scenarios docs --record-suite RUN_DIR") from exc


def load_json(path: Path, how: str) -> dict[str, Any]:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError) as exc:
        raise DocsError(f"{path}: cannot read the benchmark data ({exc}); record it with {how}") from exc


def load_csv(path: Path) -> list[dict[str, str]]:
    try:
        with open(path, newline="") as f:
            return list(csv.DictReader(f))
    except OSError as exc:
        raise DocsError(f"{path}: cannot read ({exc})") from exc


# --------------------------------------------------------------------------- tables
def _f(v: Any, digits: int = 3) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def _md(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header),
            *("| " + " | ".join(r) + " |" for r in rows)]


def _measured(suite: Mapping[str, Any]) -> str:
    m = suite["measured"]
    return f"Measured on {m['machine']}, {m['date']}, at commit {m['commit']} (`docs/data/suite.json`)."


def table_readme_suite(suite: Mapping[str, Any], study, confirm, bench) -> list[str]:
    sc = suite["scenarios"]
    rows = []
    for name, what in HEADLINE:
        arms = sc[name]["arms"]
        rows.append([f"`{name}`", what, _f(arms["adaptive"]["steady_state_error_vx"]),
                     _f(arms["pd_only"]["steady_state_error_vx"]), _f(arms["adaptive"]["convergence_time_s"], 2)])
    verdicts = [s["verdict"] for s in sc.values()]
    passed = sum(v == "pass" for v in verdicts)
    return [*_md(["scenario", "perturbation", "adaptive `sse_vx`", "PD-only `sse_vx`", "adaptive `t_conv`"], rows),
            "", f"{passed} of {len(verdicts)} scenarios pass every claim check. {_measured(suite)}"]


def table_suite(suite: Mapping[str, Any], study, confirm, bench) -> list[str]:
    rows = []
    for name in sorted(suite["scenarios"]):
        s = suite["scenarios"][name]
        for arm, a in s["arms"].items():
            rows.append([f"`{name}`", arm, "yes" if a["fell"] else "no", _f(a["steady_state_error_vx"]),
                         _f(a["steady_state_error_vy"]), _f(a["steady_state_error_vy_stride"]),
                         _f(a["steady_state_error_yaw_rate"]), _f(a["convergence_time_s"], 2), s["verdict"]])
    return [*_md(["scenario", "arm", "fell", "sse_vx", "sse_vy", "sse_vy2", "sse_yaw", "t_conv_s", "verdict"], rows),
            "", _measured(suite)]


def table_rl_levels(suite: Mapping[str, Any], study, confirm, bench) -> list[str]:
    arms = suite["scenarios"]["compare_staircase_rl"]["arms"]
    levels = arms["adaptive"]["level_errors_vx"]
    rows = [[arm, *(_f(v["error_vx"]) for v in a["level_errors_vx"])] for arm, a in arms.items()]
    return [*_md(["arm", *(f"{v['vx_des']:g} m/s from {v['t_s']:g} s" for v in levels)], rows), "", _measured(suite)]


def _beats(r: Mapping[str, str]) -> str:
    ok = "PASS" if float(r["beats_pct"]) >= 90.0 else "FAIL"
    return f"{r['beats_pct']} % [{r['beats_lo']}, {r['beats_hi']}] {ok}"


def _never(r: Mapping[str, str]) -> str:
    return "PASS" if int(r["never_listed"]) == 0 else f"FAIL: {r['never_listed']}"


def table_readme_study(suite, study: Sequence[Mapping[str, str]], confirm, bench) -> list[str]:
    rows = []
    for variant, what in SHIPPED_DESIGNS:
        mine = [r for r in study if r["variant"] == variant and not r["note"]]
        if not mine:
            continue
        sets = ", ".join(r["set"] for r in mine)
        confirmed = [r for r in mine if r["never_confirmed"]]
        if confirmed:
            never = f"{sum(r['never_confirmed'] == 'PASS' for r in confirmed)} of {len(confirmed)} (confirmed on fresh runs)"
        else:
            never = f"{sum(int(r['never_listed']) == 0 for r in mine)} of {len(mine)} (majority of five runs)"
        beats = sum(float(r["beats_pct"]) >= 90.0 for r in mine)
        falls = f"{sum(int(r['falls']) for r in mine)} / {sum(int(r['falls_against']) for r in mine)}"
        spread = [(float(r["median_settled_mps"]), float(r["median_settled_against_mps"])) for r in mine]
        med = " / ".join(f"{min(v):.3f}-{max(v):.3f}" for v in zip(*spread))
        rows.append([f"`{variant}`: {what}", sets, falls, never, f"{beats} of {len(mine)}", med])
    return [*_md(["design (`robustness_random --variant`)", "sets of 100 robots", "falls, it / PD-only (500 runs per set)",
                  "sets where it never falls where PD-only walks", "sets where it beats PD-only (>= 90 % of contested robots)",
                  "median settled error, it / PD-only (m/s)"], rows),
            "", "From `docs/data/robustness_study.csv` (each row names the commit that recorded it)."]


def table_study(suite, study: Sequence[Mapping[str, str]], confirm, bench) -> list[str]:
    rows = []
    for r in study:
        where = r["set"] + (f" ({r['note']})" if r["note"] else "")
        rows.append([f"`{r['design']}`" + (f" (`{r['variant']}`)" if r["variant"] else ""), where,
                     r["arm"], f"{r['falls']} / {r['falls_against']}", _never(r),
                     f"{r['chance_mean']} [{r['chance_lo']}, {r['chance_hi']}]", r["never_confirmed"] or "-",
                     _beats(r), f"{r['median_settled_mps']} / {r['median_settled_against_mps']}", r["recorded_in"]])
    return _md(["campaign design", "set", "arm", "falls, arm / PD-only", "never (majority of 5)",
                "chance level", "never, confirmed", "beats PD-only", "median settled error (m/s)", "recorded in"], rows)


def table_confirm(suite, study, confirm: Sequence[Mapping[str, str]], bench) -> list[str]:
    rows = [[r["set"], r["robot"], f"{r['falls_of_5']} / {r['falls_against_of_5']}",
             f"{r['falls']} / {r['falls_against']}", f"{r['only_falls']} / {r['only_falls_against']}",
             r["p_one_sided"]] for r in confirm]
    return _md(["set", "robot", "falls of 5, adaptive / PD-only", "falls on 40 fresh runs",
                "only one arm fell, adaptive / PD-only", "one-sided p"], rows)


def _bench_measured(data: Mapping[str, Any], name: str, what: str = "Measured") -> str:
    m = data["measured"]
    load = ", ".join(f"{x:.2f}" for x in m["load_average"])
    return (f"{what} on {m['machine']} ({m['cpu_count']} cores), {m['date']}, load average {load} (1, 5, 15 min) "
            f"at the end, at commit {m['commit']} (`{(BENCH_REL / name).as_posix()}`).")


def _met(value: float, target: float) -> str:
    return "yes" if value >= target else "no"


def _compared(data: Mapping[str, Any]) -> str:
    """Whether a ``bench_suite.py --compare`` run's outputs equal the compared run's."""
    compared = data.get("compare")
    return "not compared" if compared is None else "yes" if not compared else f"no ({len(compared)} differences)"


def table_bench_suite(suite, study, confirm, bench) -> list[str]:
    data = bench["suite"]
    f = data["figures"]
    target = BENCH_TARGETS["suite"]
    compared = data.get("compare")
    rows = [["main job / physics limit (2 x bare `mj_step` in the same run), by CPU time",
             f"{f['physics_fraction_cpu']:.2f}", f">= {target}", _met(f["physics_fraction_cpu"], target)],
            ["the same by wall time", f"{f['physics_fraction']:.2f}", f">= {target} (quiet machine)",
             _met(f["physics_fraction"], target)],
            ["simulated s; wall s; CPU s of all its processes", f"{f['sim_s']:.0f}; {f['wall_s']:.1f}; {f['cpu_s']:.1f}",
             "", ""],
            ["CPU s: the arms; writing the results; worker start-up; the rest (the parent)",
             f"{f['arms_cpu_s']:.1f}; {f['writing_cpu_s']:.1f}; {f['worker_startup_cpu_s']:.1f}; {f['rest_cpu_s']:.1f}",
             "", ""],
            ["the physics limit, CPU s (bare `mj_step` on each scenario's plant)",
             f"{f['physics_fraction_cpu'] * f['cpu_s']:.1f}", "", ""],
            ["every `timeseries.csv` and `summary.json` metric identical to the compared run", _compared(data), "yes",
             "" if compared is None else _met(0 if compared else 1, 1)]]
    bare = bench["suite_no_plots"]
    g = bare["figures"]
    rows += [["without the plots (`--no-plots`): main job / physics limit, by CPU time; by wall time",
              f"{g['physics_fraction_cpu']:.2f}; {g['physics_fraction']:.2f}", "", ""],
             ["without the plots: wall s; CPU s of all its processes; the same outputs but the plots",
              f"{g['wall_s']:.1f}; {g['cpu_s']:.1f}; {_compared(bare)}", "", ""]]
    return [*_md(["`bench_suite.py`, the whole suite, `--jobs 2`", "measured", "target", "met"], rows), "",
            _bench_measured(data, "suite.json") + " "
            + _bench_measured(bare, "suite_no_plots.json", "Without the plots: measured")]


def table_bench_cosim(suite, study, confirm, bench) -> list[str]:
    data = bench["cosim"]
    bare = data["bare_mj_step"]["rtf_cpu"]
    rows = [["bare `mj_step`", f"{bare:.2f}", "1.00", ""]]
    for key, label, target in (("plant_only", "plant + Python controller, zero offsets (the master's loop)", None),
                               ("inprocess", "in-process regulator core, Python controller", None),
                               ("fmu", "pythonfmu regulator FMU, Python controller", 0.5),
                               ("native_fmu", "native regulator FMU, Python controller", None),
                               ("native_fmu_c_controller", "native regulator FMU + C controller (the run's default)",
                                0.8)):
        rate = data[key]["rtf_cpu"]
        rows.append([label, f"{rate:.2f}", f"{rate / bare:.2f}", "" if target is None else f">= {target}"])
    for key, label, target in (("libcosim_ssp", "libcosim, `CassieAVR.ssp` (both FMUs pythonfmu)", 0.5),
                               ("master_plant_fmu", "our master, `--plant fmu` (pythonfmu plant FMU)", None)):
        if key in data.get("system", {}):
            rate = data["system"][key]["rtf_cpu"]
            rows.append([label, f"{rate:.2f}", f"{rate / bare:.2f}", "" if target is None else f">= {target}"])
    lines = _md(["loop (`nominal`, adaptive arm)", "simulated s per CPU s", "/ bare `mj_step`", "target"], rows)
    if "c_host" in data:  # both loops without their initialization (the master's: loop_cpu_s)
        host, ours = data["c_host"]["c_host"]["rtf_cpu"], data["c_host"]["master"]["rtf_cpu"]
        ratio, target = ours / host, BENCH_TARGETS["master_over_c_host"]
        lines += ["", *_md(["native plant FMU + native regulator FMU", "simulated s per CPU s", "/ bare `mj_step`"],
                           [["the plain C host (`tests/support/native/fmi2_loop_host.c`)", f"{host:.2f}",
                             f"{host / bare:.2f}"],
                            ["our master (`--plant fmu`, fmpy)", f"{ours:.2f}", f"{ours / bare:.2f}"],
                            *([["our master, the whole arm (FMU extraction and initialization included)",
                                f"{data['c_host']['master_arm']['rtf_cpu']:.2f}",
                                f"{data['c_host']['master_arm']['rtf_cpu'] / bare:.2f}"]]
                              if "master_arm" in data["c_host"] else [])]),
                  "", f"Our master / the C host: {ratio:.2f} (target >= {target}: {'met' if ratio >= target else 'not met'})."]
    return [*lines, "", f"{data['duration_s']:g} simulated s per loop, best of {data['repeat']}. "
            + _bench_measured(data, "cosim.json")]


def table_bench_campaign(suite, study, confirm, bench) -> list[str]:
    data = bench["campaign"]
    rows = []
    for label, res in data["results"].items():
        for r in res["runs"]:
            rows.append([label, str(r["workers"]), f"{r['wall_s']:.1f}", f"{r['cpu_s']:.1f}", f"{r['rate_cpu']:.2f}",
                         f"{r['rate_over_physics']:.2f}", f"{r['rate_wall_per_worker']:.2f}",
                         f"{res['scaling']:.2f}" if r["workers"] == 2 else "",
                         f"{res['fixed_s'][r['workers'] - 1]:.1f}",
                         "; ".join(f"{v:.2f}" for v in r["cpu_over_physics"].values())])
    lines = _md(["set-up", "workers", "wall s", "CPU s", "simulated s per CPU s", "/ bare `mj_step`",
                 "simulated s per wall s per worker", "scaling wall(1)/wall(2)", "fixed wall s per campaign",
                 "CPU s per CPU s of bare `mj_step`: plant; arms' loops; runs; campaign"], rows)
    return [*lines, "", f"`robustness_random`, {data['samples']} samples x {len(data['arms'])} arms "
            f"({', '.join(data['arms'])}) x 25 simulated s; bare `mj_step` on the samples' plants: "
            f"{data['physics']['rate_cpu']:.2f} simulated s per CPU s; targets: >= {BENCH_TARGETS['campaign_rate']} of it "
            f"per worker, scaling >= {BENCH_TARGETS['campaign_scaling']}; CPU s: "
            + data["cpu_counted"] + ". The last column splits the CPU time, each part against bare `mj_step` "
            "on the same simulated seconds: the plant (`mj_step` and the walking controller), the arms' loops "
            "(the plant, the regulator FMU's calls, the recording), the runs' own processes (model, loops, "
            f"results), the whole campaign (the ratio's CPU s); {BENCH_TARGETS['campaign_rate']} per worker needs the "
            f"whole campaign at {1 / BENCH_TARGETS['campaign_rate']:.2f} or below. The fixed wall time per campaign (the "
            "campaign's wall time minus its tasks' wall time per worker: cluster start and close, validation, report) "
            "does not grow with the samples: the fewer the samples, the more it weighs on the rate. "
            + _bench_measured(data, "campaign.json")]


TABLES: dict[str, Callable[..., list[str]]] = {
    "readme_suite": table_readme_suite,
    "suite": table_suite,
    "rl_levels": table_rl_levels,
    "readme_study": table_readme_study,
    "study": table_study,
    "confirm": table_confirm,
    "bench_suite": table_bench_suite,
    "bench_cosim": table_bench_cosim,
    "bench_campaign": table_bench_campaign,
}


# --------------------------------------------------------------------------- pages
def render_page(text: str, tables: Mapping[str, str], where: str) -> str:
    """``text`` with every generated block replaced by ``tables[NAME]``."""
    out, pos = [], 0
    for m in BEGIN.finditer(text):
        if m.start() < pos:
            continue
        end = text.find(END, m.end())
        if end < 0:
            raise DocsError(f"{where}: table {m.group(1)!r} has no {END!r}")
        if m.group(1) not in tables:
            raise DocsError(f"{where}: unknown table {m.group(1)!r} (one of {', '.join(sorted(tables))})")
        out += [text[pos:m.end()], tables[m.group(1)], "\n"]
        pos = end
    out.append(text[pos:])
    return "".join(out)


def all_tables(root: Path | None = None) -> dict[str, str]:
    """Every table, from the data of the clone at ``root`` (default: this one)."""
    data = (REPO_ROOT if root is None else root) / DATA_REL
    suite = load_suite(data / SUITE_DATA.name)
    study, confirm = load_csv(data / STUDY_DATA.name), load_csv(data / CONFIRM_DATA.name)
    bench = {name: load_json(data / BENCH_REL.name / f"{name}.json", f"{command} --json FILE")
             for name, command in BENCHMARKS.items()}
    return {name: "\n".join(fn(suite, study, confirm, bench)) for name, fn in TABLES.items()}


def pages(root: Path | None = None, tables: Mapping[str, str] | None = None) -> dict[Path, tuple[str, str]]:
    """Every page as (text now, text generated)."""
    root = REPO_ROOT if root is None else root
    tables = all_tables(root) if tables is None else tables
    out = {}
    for rel in PAGES:
        path = root / rel
        try:
            text = path.read_text()
        except OSError as exc:
            raise DocsError(f"{path}: cannot read ({exc}); the docs are generated in a clone of the repository") from exc
        out[path] = (text, render_page(text, tables, rel))
    return out


def stale(root: Path | None = None, tables: Mapping[str, str] | None = None) -> list[str]:
    """The pages whose generated blocks differ from the data (and which blocks)."""
    root = REPO_ROOT if root is None else root
    problems = []
    for path, (now, generated) in pages(root, tables).items():
        if now != generated:
            names = [m.group(1) for m in BEGIN.finditer(now)]
            ours = dict(zip(names, _blocks(now))), dict(zip(names, _blocks(generated)))
            differ = [n for n in names if ours[0].get(n) != ours[1].get(n)]
            problems.append(f"{path.relative_to(root)}: table {', '.join(differ)} differs from docs/data "
                            "(run python -m scenarios docs)")
    return problems


def _blocks(text: str) -> list[str]:
    return [text[m.end():text.find(END, m.end())] for m in BEGIN.finditer(text)]


def write(root: Path | None = None) -> list[Path]:
    changed = []
    for path, (now, generated) in pages(root).items():
        if now != generated:
            path.write_text(generated)
            changed.append(path)
    return changed


def add_parser(sub) -> None:
    sp = sub.add_parser("docs", help="write the results tables of README.md and docs/ from docs/data "
                                     "(--check: only list the stale ones)")
    g = sp.add_mutually_exclusive_group()
    g.add_argument("--check", action="store_true", help="change nothing; exit 1 if a page differs from the data")
    g.add_argument("--record-suite", metavar="RUN_DIR", type=Path,
                   help="first record docs/data/suite.json from a complete suite run in RUN_DIR")
    sp.set_defaults(func=cmd_docs)


def cmd_docs(args) -> int:
    import sys

    try:
        if args.check:
            problems = stale()
            for p in problems:
                print(p, file=sys.stderr)
            return 1 if problems else 0
        if args.record_suite is not None:
            print(f"recorded {record_suite(args.record_suite)}")
        for path in write():
            print(f"wrote {path}")
    except DocsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0
