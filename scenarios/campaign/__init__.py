"""Robustness campaigns: many sampled scenarios x arms, run on Dask, one CSV of results.

- :mod:`scenarios.campaign.spec`: campaign files (TOML) -> a validated :class:`Campaign`
  (base scenario, factors with their distributions, sample count, seed; ``extends`` and
  ``[variants]`` resolved);
- :mod:`scenarios.campaign.catalog`: the built-in campaign files and their variants (tomllib
  only: the command line's help lists them);
- :mod:`scenarios.campaign.sampling`: the seeded draws (uniform, randint, choice, grid,
  Latin hypercube) and the concrete scenario document of each sample;
- :mod:`scenarios.campaign.tomlw`: the small TOML writer for those documents;
- :mod:`scenarios.campaign.task`: what runs on a Dask worker (one sample, all its arms,
  in a fresh ``python -m scenarios run`` process);
- :mod:`scenarios.campaign.store`: the campaign folder (manifest, lock, streamed CSV);
- :mod:`scenarios.campaign.execute`: the cluster, the submission loop, progress, resume;
- :mod:`scenarios.campaign.analysis` / :mod:`scenarios.campaign.plots`: ``campaign.md``;
- :mod:`scenarios.campaign.cli`: ``python -m scenarios campaign``.

Built-in campaign files live in ``scenarios/campaigns/*.toml``.
"""
