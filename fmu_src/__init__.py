"""The FMUs' sources, in layers that import downward only:

- ``core/``: the regulator itself, numpy only, and in ``core/c/`` its C twin's numerics (the
  same doubles);
- ``fmi/``: the FMI layer every FMU shares: the table of phase rules, the native FMUs' common C
  and state-blob check, the FMI standard headers, the pythonfmu slaves' base and state blob;
- ``regulator_fmu/``: the regulator's FMUs: the pythonfmu slave, its C ``guard/``, and the
  ``native/`` FMI 2.0/3.0 wrappers over ``core/c``;
- ``plant_fmu/``: the CassiePlant pythonfmu slave and its core over ``plant`` (the plant
  imports nothing of ``fmu_src``);
- ``command_source/``: the CommandSource FMU (C);
- ``packing/``: build-time helpers of ``build.py`` (never inside an FMU).

Inside an FMU the Python modules travel as one package imported under a name private to the
build (``packing/pack.py``), their absolute project imports made package-relative.
"""
