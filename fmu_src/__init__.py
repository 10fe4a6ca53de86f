"""Sources of the AdaptiveVelocityRegulator FMU (numpy only).

The modules import each other package-relative: inside an FMU they travel as one package
imported under a name private to the build (``avr_packaging/pack.py``).  Nothing here may
import mujoco, the plant or the scenarios; the exception is ``cassie_plant_slave.py``, the
slave of the other FMU (CassiePlant), which imports the plant's core (see its docstring).
"""
