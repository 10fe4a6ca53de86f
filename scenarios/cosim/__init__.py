"""The co-simulation master: an fmpy-driven loop over a plant (in-process or the CassiePlant FMU) and a regulator (FMU or in-process), with time from an integer step counter."""
