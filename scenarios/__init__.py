"""Co-simulation scenarios: the master and the experiments that use it, in layers that import
downward only:

- :mod:`scenarios.cli` / :mod:`scenarios.report`: ``python -m scenarios`` and ``report DIR``;
- :mod:`scenarios.run`, :mod:`scenarios.campaign`, :mod:`scenarios.ssp`, :mod:`scenarios.gaits`,
  :mod:`scenarios.rl_hzd`: the experiments (the suite's runs, Monte-Carlo campaigns on Dask,
  SSP export and other masters, the gait calibration, the RL-HZD baseline);
- :mod:`scenarios.results`: metrics, CSV, summary.json, plots, videos, the results folder;
- :mod:`scenarios.cosim`: the fmpy co-simulation master, the FMI host, the plant and regulator
  paths;
- :mod:`scenarios.lang`: scenario files (TOML) -> validated frozen dataclasses, and the plant
  a scenario asks for;
- :mod:`scenarios.errors`: the exceptions every layer raises.

The paper suite lives in ``scenarios/suite/*.toml``, the campaigns in ``scenarios/campaigns/``.
"""
