"""Co-simulation scenarios: the master loop, scenario files, metrics, CLI and report.

- :mod:`scenarios.spec`: TOML scenario files -> validated frozen dataclasses;
- :mod:`scenarios.master`: the fmpy co-simulation master (FMU or in-process regulator);
- :mod:`scenarios.metrics`: pure metric functions over the master's structured array;
- :mod:`scenarios.output` / :mod:`scenarios.report`: csv, summary.json, plots, report.md;
- :mod:`scenarios.cli`: ``python -m scenarios list|validate|run|report``.

The paper suite lives in ``scenarios/suite/*.toml``.
"""
