"""Names and the standing pose the plant, the nominal controller, the master and the regulator share.

Cassie's names are the same in both models (Menagerie's ``agility_cassie`` and OSU's
``cassie.xml``): joints and actuators are ``{side}-{joint}``, the pelvis is one body.

``OFFSET_JOINTS`` are the six joints the regulator's ``delta_*`` outputs offset, in the
regulator's output order; ``tests`` ties them to ``fmu_src.core.avr_core.OUTPUT_JOINTS``
(``fmu_src`` is vendored into the FMU alone, so it cannot import them from here).
"""

OFFSET_JOINTS = (
    "swing_hip_pitch", "swing_knee", "swing_hip_roll",
    "stance_hip_roll", "stance_hip_pitch", "stance_knee",
)
#: The regulator's output names, one per offset joint (rad).
OFFSET_NAMES = tuple(f"delta_{joint}" for joint in OFFSET_JOINTS)

#: The legs, left first (the order of every per-leg array in the package).
SIDES = ("left", "right")
#: Name of the pelvis (torso) body; the floating base joint(s) sit on it.
PELVIS_BODY = "cassie-pelvis"
#: Torso mass (the pelvis body's) of both models, kg; "torso" is the name scenario files and
#: the plant FMU's parameters use.
NOMINAL_TORSO_MASS_KG = 10.33

#: Motor joints of one leg, in actuator order (each motor has its joint's name).
MOTOR_JOINTS = ("hip-roll", "hip-yaw", "hip-pitch", "knee", "foot")
#: Passive (spring) joints of one leg the controller reads.
PASSIVE_JOINTS = ("shin", "tarsus", "heel-spring")
#: Every named joint of one leg, root to foot.
LEG_JOINTS = ("hip-roll", "hip-yaw", "hip-pitch", "achilles-rod", "knee", "shin",
              "tarsus", "heel-spring", "foot-crank", "plantar-rod", "foot")

#: Motor names (also the names of the joints they drive), left leg first.
ACTUATOR_NAMES: tuple[str, ...] = tuple(f"{s}-{j}" for s in SIDES for j in MOTOR_JOINTS)
#: Every named joint of the robot (the floating base joint(s) are unnamed).
JOINT_NAMES: tuple[str, ...] = tuple(f"{s}-{j}" for s in SIDES for j in LEG_JOINTS)

#: Name of the standing keyframe every loaded model carries.
HOME_KEY = "home"
# Standing pose of Menagerie's ``home`` keyframe (agility_cassie/cassie.xml, MIT), per
# joint name; radians, or a unit quaternion (w, x, y, z) for the ball joints. The loader
# gives models without a ``home`` keyframe (the OSU file) the same one.
#: Pelvis position of the standing pose, m: the feet then just touch a z = 0 floor.
HOME_PELVIS_POS_M = (0.0, 0.0, 1.0059301)
#: Pelvis orientation of the standing pose (w, x, y, z): level, facing +x.
HOME_PELVIS_QUAT = (1.0, 0.0, 0.0, 0.0)
#: Joint positions of the standing pose by joint name.
HOME_JOINT_QPOS: dict[str, tuple[float, ...]] = {
    "left-hip-roll": (0.00449956,),
    "left-hip-yaw": (0.0,),
    "left-hip-pitch": (0.497301,),
    "left-achilles-rod": (0.9786097486736136, -0.016410395785484994,
                          0.017776595434617837, -0.20429794753223648),
    "left-knee": (-1.1997,),
    "left-shin": (0.0,),
    "left-tarsus": (1.42671,),
    "left-heel-spring": (-2.25907e-06,),
    "left-foot-crank": (-1.52439,),
    "left-plantar-rod": (1.50645,),
    "left-foot": (-1.59681,),
    "right-hip-roll": (-0.00449956,),
    "right-hip-yaw": (0.0,),
    "right-hip-pitch": (0.497301,),
    "right-achilles-rod": (0.9787396935407306, 0.0038686987886476744,
                           -0.015157195254036375, -0.20450893596493583),
    "right-knee": (-1.1997,),
    "right-shin": (0.0,),
    "right-tarsus": (1.42671,),
    "right-heel-spring": (0.0,),
    "right-foot-crank": (-1.52439,),
    "right-plantar-rod": (1.50645,),
    "right-foot": (-1.59681,),
}

#: The nominal walking controller's implementations: ``python`` (``plant/controller.py``) and
#: ``native`` (the same operations in C, ``plant/native/``); ``CassieWalker(controller=...)``.
CONTROLLERS = ("python", "native")
