"""One ``python -m scenarios run`` after its checks: the tasks, their outcomes, each
scenario's folder published once all its arms end, the table and the exit status."""
from __future__ import annotations

import dataclasses
import logging
import signal
import sys
import threading
import time
from contextlib import contextmanager
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fmu_src.core.avr_errors import AvrError

if TYPE_CHECKING:  # pragma: no cover
    from scenarios.run.options import RunOptions

log = logging.getLogger("scenarios")


class RunSession:
    """One ``run``: the tasks, their outcomes, each scenario published once all its arms end."""

    def __init__(self, options: "RunOptions", results_dir, plan) -> None:
        from scenarios.run.runner import StopFlag

        self.options, self.results_dir, self.plan = options, results_dir, plan
        self.stop = StopFlag()
        self.outcomes: dict[str, dict[str, Any]] = {s.name: {} for s in plan.run}
        self.summaries: dict[str, dict[str, Any]] = {s["scenario"]: s for s in plan.kept}
        self.left_as_were: list[str] = []
        self.write_errors: list[str] = []
        self.wall_s = 0.0
        #: summary.json's ``path``: the implementations the results come from (the FMUs hashed once).
        self.path = options.path_record()

    def run(self) -> None:
        from tqdm import tqdm

        from scenarios.run import runner

        tasks = [(s, a.name) for s in self.plan.run for a in s.arms]
        jobs = min(self.options.jobs, max(1, len(tasks)))
        if jobs == 1:
            bar = tqdm(total=sum(s.n_comm_steps for s, _ in tasks), unit="step", desc="co-simulation",
                       disable=None, leave=False)
        else:
            bar = tqdm(total=len(tasks), unit="arm", desc="co-simulation", disable=None, leave=False)
        wall0 = time.perf_counter()
        with bar, _sigint_sets(self.stop):
            runner.run_tasks(tasks, dataclasses.replace(self.options, jobs=jobs), stop=self.stop,
                             on_outcome=self.on_outcome, progress=bar.update)
        self.wall_s = time.perf_counter() - wall0

    def on_outcome(self, scenario, outcome):
        got = self.outcomes[scenario.name]
        got[outcome.arm] = outcome
        if len(got) == len(scenario.arms):
            return self.finish(scenario, list(got.values()))
        return None

    def finish(self, scenario, outcomes: list):
        """The job that writes the scenario's folder (staged, renamed into place when it is
        done: :meth:`published`), or None. Only complete results replace earlier ones: a
        failed or interrupted scenario leaves an existing folder as it was."""
        from scenarios.results import output
        from scenarios.run import runner

        if not any(o.started for o in outcomes):
            return None  # an interrupt kept every arm from starting: nothing to say on disk
        replace = scenario.name in self.plan.replace
        if replace and any(o.status != "complete" for o in outcomes):
            self.left_as_were.append(scenario.name)
            if not self.stop.requested:  # for the table and the exit status
                self.summaries[scenario.name] = output.build_summary(scenario, self.options.regulator, outcomes,
                                                                     path=self.path)
            return None
        try:
            staged = self.results_dir.stage(scenario.name)
        except OSError as exc:
            self.write_errors.append(f"{scenario.name}: results not written: {exc}")
            return None
        write = partial(output.write_results, plots=self.options.plots, videos=self.options.render,
                        path=self.path)
        return runner.Job(write, (staged, scenario, self.options.regulator, outcomes),
                          partial(self.published, scenario.name, replace))

    def published(self, name: str, replace: bool, summary, error: BaseException | None) -> None:
        """Rename the written folder into place, or say why it was not written."""
        if error is None:
            try:
                self.results_dir.commit(name, replace=replace)
                self.summaries[name] = summary
                return
            except (OSError, AvrError) as exc:  # e.g. the disk is full: the other scenarios go on
                error = exc
        if not isinstance(error, (OSError, AvrError)):
            log.error("%s: writing the results failed", name, exc_info=error)
        self.results_dir.discard(name)
        self.write_errors.append(f"{name}: results not written: {error}")

    def report(self, scenarios: list, out_root: Path) -> int:
        """Print the table (or, after Ctrl-C, one line); the exit status."""
        from scenarios.results import output

        ordered = [self.summaries[s.name] for s in scenarios if s.name in self.summaries]
        if self.stop.requested:
            line = _interrupted_line(scenarios, self.summaries, self.left_as_were, out_root)
            print(line + "".join(f"; {e}" for e in self.write_errors), file=sys.stderr)
            return 130
        print(output.format_table(ordered))
        for name in self.left_as_were:
            print(f"{name}: this run's results are {self.summaries[name]['status']}; the earlier results in "
                  f"{out_root / name} were kept", file=sys.stderr)
        for err in self.write_errors:
            print(err, file=sys.stderr)
        n_arms = sum(len(s.arms) for s in self.plan.run)
        sim = sum((m.get("sim_s") or 0.0) for s in self.plan.run if s.name in self.summaries
                  for m in self.summaries[s.name]["arms"].values())
        kept = f"{len(self.plan.kept)} kept as complete (--resume), " if self.plan.kept else ""
        print(f"\n{len(scenarios)} scenario(s), {kept}{n_arms} arm run(s), {sim:.1f} simulated s in "
              f"{self.wall_s:.1f} s wall (--jobs {self.options.jobs}, regulator {self.options.regulator}, controller "
              f"{self.options.controller}); results in "
              f"{out_root}/ (python -m scenarios report {out_root})")
        failed = self.write_errors or any(su["status"] != "complete" for su in ordered)
        if failed:
            return 1
        if self.options.require_pass:
            overall = {su["scenario"]: output.verdict(su).get("overall", "n/a") for su in ordered}
            short = [f"{name}: {v}" for name, v in overall.items() if v != "pass"]
            if short:
                print(f"--require-pass: {len(short)} of {len(ordered)} scenario verdict(s) are not pass: "
                      + "; ".join(short), file=sys.stderr)
                return 3
        return 0


def _interrupted_line(scenarios: list, summaries: dict, left_as_were: list[str], out_root: Path) -> str:
    status = {n: s["status"] for n, s in summaries.items()}
    complete = sum(1 for s in scenarios if status.get(s.name) == "complete")
    flagged = sorted(n for n, st in status.items() if st != "complete")
    parts = [f"{complete} of {len(scenarios)} scenario(s) complete in {out_root}/"]
    if flagged:
        parts.append(f"{', '.join(flagged)} marked incomplete")
    if left_as_were:
        parts.append(f"{', '.join(left_as_were)} left as before")
    return f"interrupted: {'; '.join(parts)}; run again with --resume to finish"


@contextmanager
def _sigint_sets(stop):
    """While inside: the first SIGINT sets ``stop`` (the run ends cleanly between steps),
    a second one raises KeyboardInterrupt (stop at once)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        if stop.requested:
            raise KeyboardInterrupt
        stop.set()

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
