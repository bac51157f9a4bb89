"""The HOAP-2 joint table: the 25 joint names, their functions and the paper's names (no MuJoCo here).

Names are the HOAP-2 motor names of the reference model. Leg joints per side (``s`` = ``l`` or ``r``):

====================  ===============  ===========  ==========================================
joint                 function         paper        axis (zero posture) / positive direction
====================  ===============  ===========  ==========================================
``sleg_joint_1``      hip yaw          (unused)     +z
``sleg_joint_2``      hip roll         **Hip1**     +x (lateral; both legs follow one signal)
``sleg_joint_3``      hip pitch        **Hip2**     +y (negative = thigh forward)
``sleg_joint_4``      knee pitch       **Knee**     +y (positive = flexion)
``sleg_joint_5``      ankle pitch      **Ankle1**   +y
``sleg_joint_6``      ankle roll       **Ankle2**   +x
====================  ===============  ===========  ==========================================

The hip nests yaw -> pitch (joint_3) -> roll (joint_2), as in the reference model and the recorded data.
"""

from __future__ import annotations

SIDES = ("l", "r")

LEG_FUNCTIONS: dict[int, str] = {
    1: "hip_yaw", 2: "hip_roll", 3: "hip_pitch", 4: "knee", 5: "ankle_pitch", 6: "ankle_roll",
}
ARM_FUNCTIONS: dict[int, str] = {
    1: "shoulder_pitch", 2: "shoulder_roll", 3: "upper_arm_twist", 4: "elbow", 5: "hand",
}
#: The paper's five controlled DOFs of each leg and the HOAP-2 joint number that carries each.
PAPER_LEG_DOFS: dict[str, int] = {"Hip1": 2, "Hip2": 3, "Knee": 4, "Ankle1": 5, "Ankle2": 6}

LEG_JOINTS: tuple[str, ...] = tuple(f"{s}leg_joint_{k}" for s in SIDES for k in range(1, 7))
ARM_JOINTS: tuple[str, ...] = tuple(f"{s}arm_joint_{k}" for s in SIDES for k in range(1, 6))
BODY_JOINTS: tuple[str, ...] = ("body_joint_1",)
HEAD_JOINTS: tuple[str, ...] = ("head_joint_1", "head_joint_2")

#: All 25 joints in the package's canonical order (every array over "all joints" uses this order).
JOINT_NAMES: tuple[str, ...] = BODY_JOINTS + LEG_JOINTS + ARM_JOINTS + HEAD_JOINTS

#: The paper's 10 controlled DOFs: Hip1, Hip2, Knee, Ankle1, Ankle2 of the left, then the right leg.
CONTROLLED_JOINTS: tuple[str, ...] = tuple(
    f"{s}leg_joint_{k}" for s in SIDES for k in PAPER_LEG_DOFS.values()
)

#: The 21 joints of the Fujitsu recordings, in the recordings' column order.
RECORDED_JOINTS: tuple[str, ...] = (
    tuple(f"rleg_joint_{k}" for k in range(1, 7))
    + tuple(f"rarm_joint_{k}" for k in range(1, 5))
    + tuple(f"lleg_joint_{k}" for k in range(1, 7))
    + tuple(f"larm_joint_{k}" for k in range(1, 5))
    + ("body_joint_1",)
)

MAX_TORQUE_NM = 9.0  # every HOAP-2 motor (reference model)
MAX_VELOCITY_RADS = 5.0  # every HOAP-2 motor (reference model)


def paper_name(joint: str) -> str | None:
    """The paper's name of a leg joint with its side (``'lleg_joint_3'`` -> ``'left Hip2'``), else None."""
    if joint not in LEG_JOINTS:
        return None
    side = "left" if joint.startswith("l") else "right"
    number = int(joint[-1])
    for name, k in PAPER_LEG_DOFS.items():
        if k == number:
            return f"{side} {name}"
    return None


def joint_function(joint: str) -> str:
    """What a joint does, e.g. ``'rleg_joint_2'`` -> ``'hip_roll'``; raises KeyError for unknown names."""
    if joint in LEG_JOINTS:
        return LEG_FUNCTIONS[int(joint[-1])]
    if joint in ARM_JOINTS:
        return ARM_FUNCTIONS[int(joint[-1])]
    if joint == "body_joint_1":
        return "waist_pitch"
    if joint in HEAD_JOINTS:
        return "neck_yaw" if joint.endswith("1") else "neck_pitch"
    raise KeyError(f"unknown HOAP-2 joint {joint!r}; known: {', '.join(JOINT_NAMES)}")


#: The joint groups that carry their own PID gains (config/pid.yaml ``kp.leg`` ...).
GROUPS: tuple[str, ...] = ("leg", "arm", "body", "head")


def group_of(joint: str) -> str:
    """'leg', 'arm', 'body' or 'head' (the groups that carry their own PID gains)."""
    if joint in LEG_JOINTS:
        return "leg"
    if joint in ARM_JOINTS:
        return "arm"
    if joint in BODY_JOINTS:
        return "body"
    if joint in HEAD_JOINTS:
        return "head"
    raise KeyError(f"unknown HOAP-2 joint {joint!r}")
