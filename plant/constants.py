"""Names the plant, the nominal controller, the master and the regulator share.

``OFFSET_JOINTS`` are the six joints the regulator's ``delta_*`` outputs offset, in the
regulator's output order; ``tests`` ties them to ``fmu_src.avr_core.OUTPUT_JOINTS``
(``fmu_src`` is vendored into the FMU alone, so it cannot import them from here).
"""

OFFSET_JOINTS = (
    "swing_hip_pitch", "swing_knee", "swing_hip_roll",
    "stance_hip_roll", "stance_hip_pitch", "stance_knee",
)
#: The regulator's output names, one per offset joint (rad).
OFFSET_NAMES = tuple(f"delta_{joint}" for joint in OFFSET_JOINTS)
