"""The FMUs' sources, in layers that import downward only:

- ``core/``: the regulator itself, numpy only (and, in ``native/``, its C twin's numerics);
- ``fmi/``: what both pythonfmu slaves share: the FMI phase rules and the FMU-state blob;
- ``regulator_fmu/``, ``plant_fmu/``: the two pythonfmu slaves (the plant's imports ``plant``);
- ``guard/``, ``native/``, ``command_source/``: the C parts (the guard in front of the
  pythonfmu regulator, the native regulator FMUs, the CommandSource FMUs);
- ``packing/``: build-time helpers of ``build.py`` (never inside an FMU).

Inside an FMU the Python modules travel as one package imported under a name private to the
build (``packing/pack.py``), their absolute project imports made package-relative.
"""
