"""Build-time helpers of ``build.py`` (never packed into an FMU): reproducible archives and
content GUIDs (:mod:`.archive`), the pythonfmu FMUs' model description and documentation
(:mod:`.describe`, :mod:`.pages`), the method rendered from ``docs/method.md`` (:mod:`.method_page`),
the fix of pythonfmu's linux64 library (:mod:`.pythonfmu_fix`), how a pythonfmu FMU carries
its code (:mod:`.pack`: one package under a name private to the build, its modules vendored
by :mod:`.vendor`) and the CassiePlant FMU's models.  The C parts are built beside their sources:
``fmu_src/regulator_fmu/guard/build_guard.py`` and ``fmu_src/regulator_fmu/native/build_native.py``.

Named ``packing``, not ``packaging``: a ``packaging`` folder on ``sys.path`` would shadow
PyPA's ``packaging`` that matplotlib and others import.
"""
