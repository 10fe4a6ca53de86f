"""Gait library calibration (``python -m scenarios.gaits.make_gaits``): walks the plant with the
PD-only regulator over the speed grid and writes ``plant/data/gait_library.json``."""
