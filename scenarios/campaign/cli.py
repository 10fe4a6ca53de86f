"""``python -m scenarios campaign NAME|FILE [--variant V] --out DIR [--workers N [--dashboard-address HOST:PORT] |
--scheduler ADDRESS | --scheduler-file FILE] [--resume] [--no-plots]``.

Validates the campaign and every sample before anything runs (exit 2 with every
problem), claims DIR (exit 2 if it holds another campaign, or this one without
``--resume``), runs the samples that are not complete on Dask, streams the rows to
``DIR/campaign.csv``, then (with ``confirm_runs``) runs the confirmation stage in
``DIR/confirm``, writes ``DIR/campaign.md`` (and its plots, unless ``--no-plots``) and prints the
table per arm.
Exit status: 0 every row complete (the stage's too); 1 some failed (they are in the CSV with the reason;
``--resume`` runs them again); 2 invalid campaign, arguments or DIR, or a scheduler that cannot be used
(unreachable, not Dask, no worker; one line); 130 interrupted.
"""
from __future__ import annotations

import argparse
import dataclasses
import functools
import logging
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from scenarios.errors import ScenarioError
from scenarios.cosim.fmus import REGULATOR_FMUS, fmu_file_problem
from scenarios.run.options import CONTROLLERS, DEFAULT_CONTROLLER, DEFAULT_REGULATOR, resolve_regulator

if TYPE_CHECKING:  # pragma: no cover
    from scenarios.campaign.execute import RunOptions

log = logging.getLogger("scenarios.campaign")


def add_parser(sub) -> None:
    """Register the ``campaign`` subcommand on the ``python -m scenarios`` parser."""
    from scenarios.campaign.catalog import listing

    sp = sub.add_parser("campaign", help="run a robustness campaign (sampled scenarios x arms) on Dask")
    sp.add_argument("campaign", metavar="NAME|FILE", help=f"a built-in campaign ({listing()}) or a campaign file")
    sp.add_argument("--variant", metavar="NAME", default=None,
                    help="one of the campaign's [variants] (listed above for the built-in ones; default: the file's "
                         "default_variant); the campaign is then named <campaign>_<variant>")
    sp.add_argument("--out", default=None, help="campaign folder (default: runs/<campaign name>)")
    where = sp.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None,
                       help="local Dask worker processes, one thread each (default: the CPU count)")
    where.add_argument("--scheduler", metavar="ADDRESS", default=None,
                       help="an existing Dask scheduler (tcp://host:8786, or tls://host:8786 with Dask's TLS "
                            "configuration, distributed.comm.tls.*); workers need a shared file system")
    where.add_argument("--scheduler-file", metavar="FILE", default=None,
                       help="an existing Dask scheduler by its scheduler file (dask scheduler --scheduler-file, "
                            "dask-jobqueue, dask-mpi)")
    sp.add_argument("--dashboard-address", metavar="HOST:PORT", default=None,
                    help="where the local cluster's Dask dashboard listens (default 127.0.0.1 and a free port: "
                         "this machine only; e.g. 0.0.0.0:8787 exposes it to the network)")
    sp.add_argument("--resume", action="store_true", help="continue the campaign in --out (skips complete samples)")
    sp.add_argument("--regulator", choices=(*REGULATOR_FMUS, "inprocess"), default=None,
                    help=f"as for run (default: the kind of the --fmu file, else {DEFAULT_REGULATOR}; every path "
                         "gives the same bits)")
    sp.add_argument("--controller", choices=CONTROLLERS, default=DEFAULT_CONTROLLER,
                    help=f"the walking controller, as for run: python or native (C; default {DEFAULT_CONTROLLER})")
    sp.add_argument("--fmu", type=Path, default=None, help="FMU file (default: dist/, built if missing or stale)")
    sp.add_argument("--rebuild-fmu", action="store_true", help="rebuild the default FMU first")
    sp.add_argument("--task-timeout", type=float, default=None, help="seconds per sample (overrides the file)")
    sp.add_argument("--retries", type=int, default=None, help="retries of a task whose worker/run process died")
    sp.add_argument("--fork-runs", action=argparse.BooleanOptionalAction, default=None,
                    help="fork each sample's run, a fresh process all the same, from a warm process per worker "
                         "(imports and the base model's check once per worker, not once per sample; the "
                         "default on Linux); --no-fork-runs: a new interpreter per run")
    sp.add_argument("--seed", type=int, default=None,
                    help="draw the samples from this seed instead of the file's: the same design on other robots "
                         "(recorded in campaign.json and campaign.md)")
    sp.add_argument("--no-plots", action="store_true",
                    help="write campaign.md without its plots (python -m scenarios report DIR writes them later)")
    sp.add_argument("--dry-run", action="store_true", help="validate and list the samples; run nothing")
    sp.set_defaults(func=cmd_campaign)


def _check_args(args) -> list[str]:
    from scenarios.campaign.spec import MAX_TASK_TIMEOUT_S

    problems = []
    if args.workers is not None and args.workers < 1:
        problems.append(f"--workers {args.workers}: must be >= 1")
    if args.task_timeout is not None and not 0 < args.task_timeout <= MAX_TASK_TIMEOUT_S:
        problems.append(f"--task-timeout {args.task_timeout:g}: must be within (0, {MAX_TASK_TIMEOUT_S:g}] s")
    if args.retries is not None and not 0 <= args.retries <= 10:
        problems.append(f"--retries {args.retries}: must be within [0, 10]")
    if args.scheduler_file is not None:
        from scenarios.campaign.execute import scheduler_file_problem

        problems += filter(None, [scheduler_file_problem(args.scheduler_file)])
    if args.dashboard_address is not None:
        problems += filter(None, [_dashboard_problem(args)])
    if args.seed is not None and not 0 <= args.seed <= 2**63 - 1:
        problems.append(f"--seed {args.seed}: must be within [0, {2**63 - 1}]")
    if args.controller == "native":
        from scenarios.run.options import controller_problem

        problems += filter(None, [controller_problem()])
    if args.fmu is not None and not Path(args.fmu).is_file():
        problems.append(fmu_file_problem("--fmu", args.fmu))
    elif args.fmu is not None and args.regulator in REGULATOR_FMUS:
        from scenarios.cosim.fmus import fmu_role_problem, fmu_version_problem

        problems += filter(None, [fmu_version_problem(args.regulator, Path(args.fmu))
                                  or fmu_role_problem("--fmu", Path(args.fmu), "regulator")])
    return problems


def _dashboard_problem(args) -> str | None:
    flag = f"--dashboard-address {args.dashboard_address}"
    if args.scheduler or args.scheduler_file:
        return f"{flag}: only for the local cluster (an existing scheduler has its own dashboard)"
    host, sep, port = args.dashboard_address.rpartition(":")
    if not sep or not port.isdigit() or not 0 <= int(port) <= 65535:
        return f"{flag}: must be HOST:PORT with a port in [0, 65535] (0: a free port), e.g. 127.0.0.1:8787"
    return None


def run_options(args) -> RunOptions:
    """The campaign's :class:`scenarios.campaign.execute.RunOptions` from the parsed arguments; an
    option left unset (None) takes RunOptions' default, written there only."""
    from scenarios.campaign import execute

    where = {"scheduler": args.scheduler, "scheduler_file": args.scheduler_file}
    given = {"dashboard_address": args.dashboard_address, "fork_runs": args.fork_runs}
    where.update({k: v for k, v in given.items() if v is not None})
    return execute.RunOptions(workers=args.workers, **where, regulator=args.regulator, controller=args.controller,
                              fmu=None, timeout_s=args.task_timeout, retries=args.retries)


def _print_samples(samples, factor_names) -> None:
    from scenarios.campaign.sampling import format_value

    print("sample  " + "  ".join(factor_names))
    for s in samples:
        print(f"{s.id}   " + "  ".join(str(format_value(s.values[f])) for f in factor_names))


def cmd_campaign(args) -> int:
    from scenarios.campaign import execute, sampling, spec
    from scenarios.campaign.report import text_table, write_report
    from scenarios.campaign.store import CampaignDir, CampaignDirError

    args.regulator = resolve_regulator(args.regulator, args.fmu)
    problems = _check_args(args)
    try:
        import distributed  # noqa: F401  (the optional `campaign` extra)
    except ImportError:
        problems.append("the campaign command needs Dask: pip install 'cassie-avr[campaign]' "
                        "(or pip install 'dask[distributed]')")
    try:
        path = spec.resolve_campaign(args.campaign)
        campaign = spec.load_campaign(path, variant=args.variant)
        if args.seed is not None and not problems:
            campaign = dataclasses.replace(campaign, seed=args.seed)
        samples = sampling.draw(campaign)
        texts = sampling.build_samples(campaign, samples)
    except ScenarioError as exc:
        problems.append(str(exc))
    if problems:
        print("\n".join(problems), file=sys.stderr)
        return 2
    names = [f.name for f in campaign.factors]
    if args.dry_run:
        _print_samples(samples, names)
        return 0
    opts = run_options(args)
    if args.scheduler or args.scheduler_file:
        try:  # before the folder is claimed: a wrong address leaves nothing behind
            execute.check_scheduler(opts)
        except execute.ConnectionFailed as exc:
            print(f"campaign {campaign.name}: {exc}", file=sys.stderr)
            return 2
    out = Path(args.out) if args.out else Path("runs") / campaign.name
    cdir = CampaignDir(out, campaign.name, texts, campaign.arm_names(), names, campaign.analysis_settings())
    try:
        cdir.open(resume=args.resume, campaign_file=path, campaign_text=campaign.resolved_text)
    except CampaignDirError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    values = {s.id: {k: sampling.format_value(v) for k, v in s.values.items()} for s in samples}
    if args.resume:
        n_done = len(cdir.complete_samples())
        print(f"resuming {campaign.name} in {out}: {n_done} of {len(samples)} samples complete, "
              f"{len(samples) - n_done} to run", file=sys.stderr)
    try:
        fmu = _fmu(args)
        if fmu is False:
            return 1
        if not _controller_ready(args):
            return 1
        opts = dataclasses.replace(opts, fmu=fmu)
        execute.run(campaign, cdir, values, opts, fmu)
        cdir.finish()
        stage_ok = not campaign.confirm_runs or _run_confirmation(campaign, out, opts, fmu)
    except execute.CampaignInterrupted as exc:
        variant = "" if args.variant is None else f" --variant {args.variant}"
        seed = "" if args.seed is None else f" --seed {args.seed}"
        print(f"interrupted: {exc.done} sample(s) finished in this run and are in "
              f"{getattr(exc, 'csv_path', cdir.csv_path)}, {exc.remaining} not run; continue with: "
              f"python -m scenarios campaign {args.campaign}{variant} --out {out}{seed} --resume", file=sys.stderr)
        return 130
    except execute.ConnectionFailed as exc:
        print(f"campaign {campaign.name}: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"campaign {campaign.name}: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    finally:
        cdir.finish()
        cdir.close()
    rc = _finish(out, functools.partial(write_report, plots=not args.no_plots), text_table)
    return rc if stage_ok else 2


def _run_confirmation(campaign, out: Path, opts, fmu) -> bool:
    """The confirmation stage (``confirm_runs``) in ``out/confirm``: every draw the "never
    falls where b walks" reading lists, on fresh replicas (:func:`sampling.confirmation`).
    Runs only once the campaign is complete (a partial campaign lists other draws); the
    stage resumes with the campaign. False (with the reason printed) if it cannot start."""
    from scenarios.campaign import analysis, execute, sampling
    from scenarios.campaign.store import CampaignDir, CampaignDirError

    data = analysis.load(out)
    if not data.complete:
        print(f"confirmation stage not run: the campaign in {out} is not complete", file=sys.stderr)
        return True  # _finish reports the incomplete campaign
    a, b = data.arms[:2]
    v = analysis.verdicts(data.verdict_rows(), a, b, metric=data.metric, replicas_a=data.replicas(a),
                          replicas_b=data.replicas(b))
    listed = v["only_a_fell"]
    if not listed:
        print(f"confirmation stage: the screen lists no draw where {a} fell and {b} walked", file=sys.stderr)
        return True
    try:
        stage, samples, of = sampling.confirmation(campaign, listed)
        texts = sampling.build_samples(stage, samples)
    except ScenarioError as exc:
        print(f"confirmation stage: {exc}", file=sys.stderr)
        return False
    names = [f.name for f in stage.factors]
    print(f"confirmation stage: {len(listed)} listed draw(s) ({', '.join(listed)}) x {campaign.confirm_runs} fresh "
          f"runs of {a} and {b} in {out / analysis.CONFIRM_DIR}", file=sys.stderr)
    sdir = CampaignDir(out / analysis.CONFIRM_DIR, stage.name, texts, stage.arm_names(), names,
                       {"confirm_of": of, "listed": listed, "runs": campaign.confirm_runs})
    try:
        sdir.open(resume=(out / analysis.CONFIRM_DIR).exists(), campaign_file=None,
                  campaign_text=campaign.resolved_text)
    except CampaignDirError as exc:
        print(f"confirmation stage: {exc} (that folder holds only the stage: remove it to run the stage "
              "afresh)", file=sys.stderr)
        return False
    try:
        values = {s.id: {k: sampling.format_value(v) for k, v in s.values.items()} for s in samples}
        execute.run(stage, sdir, values, opts, fmu)
    except execute.CampaignInterrupted as exc:
        exc.csv_path = sdir.csv_path  # the message names the stage's rows
        raise
    finally:
        sdir.finish()
        sdir.close()
    return True


def _controller_ready(args) -> bool:
    """With ``--controller native``: the C controller built once here, before the tasks load it."""
    if args.controller != "native":
        return True
    from plant.native.native_ctrl import cached_library_path
    from plant.sim import NATIVE_CACHE

    try:
        cached_library_path(NATIVE_CACHE)
    except Exception as exc:
        print(f"--controller native: cannot build the C walking controller: {exc}; --controller python runs the "
              "same controller in Python (the same results)", file=sys.stderr)
        return False
    return True


def _fmu(args):
    """The regulator's FMU path (built when missing/stale), None in-process, False on error."""
    if args.regulator == "inprocess":
        return None
    from scenarios.cosim.fmus import ensure_fmu

    try:
        return str(Path(ensure_fmu(args.fmu, rebuild=args.rebuild_fmu, regulator=args.regulator)).resolve())
    except Exception as exc:
        print(f"cannot get the FMU: {exc}", file=sys.stderr)
        return False


def _finish(out: Path, write_report, text_table) -> int:
    from scenarios.campaign import analysis

    report = write_report(out)
    data = analysis.load(out)
    print(text_table(data))
    print(f"\n{len(data.rows)} of {data.expected_rows} rows, {data.failed_rows} failed; {out / 'campaign.csv'}; "
          f"report {report}")
    stage = analysis.load_confirmation(out)
    if stage is not None:
        print(f"confirmation stage: {len(stage.rows)} of {stage.expected_rows} rows, {stage.failed_rows} failed; "
              f"{stage.root / 'campaign.csv'}")
    return 0 if data.complete and (stage is None or stage.complete) else 1
