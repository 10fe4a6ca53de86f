"""Sources of the AdaptiveVelocityRegulator FMU (numpy only).

Every module here is also copied flat into the FMU's ``resources/`` folder, so the
modules import each other with a fallback from the package-relative to the top-level
name; nothing here may import mujoco, the plant or the scenarios.  The exception is
``cassie_plant_slave.py``, the slave of the other FMU (CassiePlant): it loads its own copy
of the plant from that FMU's resources (see its docstring).
"""
