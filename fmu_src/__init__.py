"""Sources of the AdaptiveVelocityRegulator FMU (numpy only).

Every module here is also copied flat into the FMU's ``resources/`` folder, so the
modules import each other with a fallback from the package-relative to the top-level
name; nothing here may import mujoco, the plant or the scenarios.
"""
