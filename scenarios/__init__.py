"""Co-simulation scenarios: the master loop, scenario files, metrics, CLI and report.

- :mod:`scenarios.lang.spec`: TOML scenario files -> validated frozen dataclasses;
- :mod:`scenarios.cosim.master`: the fmpy co-simulation master (FMU or in-process regulator);
- :mod:`scenarios.results.metrics`: pure metric functions over the master's structured array;
- :mod:`scenarios.results.output` / :mod:`scenarios.report`: csv, summary.json, plots, report.md;
- :mod:`scenarios.cli`: ``python -m scenarios list|validate|run|report`` (``run``: :mod:`scenarios.run.command`).

The paper suite lives in ``scenarios/suite/*.toml``.
"""
