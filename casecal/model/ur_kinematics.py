"""The ``kinematics:`` file of Universal Robots' ROS description packages.

ur_description builds its six joints from this file: each joint's origin (x, y, z, roll,
pitch, yaw, m and rad) relative to the previous link, the first relative to
``base_link_inertia`` (which is UR's DH base frame), every joint turning about its z axis;
``tool0`` is the ``wrist_3_link`` frame. A UR's factory calibration, or casecal's, goes to
the robot's ROS stack through this file (``kinematics_params_file``).

Writing: a URDF robot from a UR URDF (its joint origins in the file's frames) or a
standard-DH robot of six revolute joints (``origin_i = Tx(a_{i-1}) Rx(alpha_{i-1}) Ry(beta)
· Tz(d_i) Rz(theta_i)``, the DH frames being UR's link frames). Reading: a URDF-convention
robot of those six joints, which reproduces the chain the file describes.

What comes after ``wrist_3_link`` (a DH a6, alpha6, beta6, a calibrated tool) has no place
in the file: `ur_kinematics_contract` says so, and `casecal.save_robot` states the loss in mm
and degrees with the controller TCP that keeps it (`casecal.model.export_check`).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import CalibrationError
from .urdf import UrdfJoint, split, transform

JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
KEYS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
FIELDS = ("x", "y", "z", "roll", "pitch", "yaw")
LIMITS = (
    ((-2 * math.pi, 2 * math.pi),) * 2 + ((-math.pi, math.pi),) + ((-2 * math.pi, 2 * math.pi),) * 3
)
"""UR e-series joint ranges (rad): ±360°, the elbow ±180°."""


def _is_identity(T: np.ndarray) -> bool:
    return bool(np.allclose(T, np.eye(4), rtol=0, atol=1e-15))


def _dh_origins(robot) -> tuple[list[np.ndarray], list[str]]:
    if robot.convention != "dh" or robot.joint_types != "RRRRRR":
        raise CalibrationError(
            f"robot {robot.name!r}: a UR kinematics file holds six revolute joints in standard "
            "DH or from a UR URDF"
        )
    origins, post = [], np.eye(4)
    for j in robot.joints:
        pre = transform((0, 0, j.d), (0, 0, j.theta))
        origins.append(post @ pre)
        post = (
            transform((j.a, 0, 0), (0, 0, 0))
            @ transform((0, 0, 0), (j.alpha, 0, 0))
            @ transform((0, 0, 0), (0, j.beta or 0.0, 0))
        )
    # what comes after wrist_3 (a6, alpha6, beta6, the tool) is not written: the check on
    # write measures and states it (`ur_kinematics_contract`)
    return origins, []


def _urdf_origins(robot) -> tuple[list[np.ndarray], list[str]]:
    from .urdf_out import _rotation_about, file_origins, offset_note

    names = [j.name for j in robot.joints]
    prefix = names[0][: -len(JOINTS[0])] if names[0].endswith(JOINTS[0]) else None
    if prefix is None or names != [prefix + n for n in JOINTS]:
        raise CalibrationError(
            f"robot {robot.name!r}: a UR kinematics file needs the joints {', '.join(JOINTS)}"
            f" (with one common prefix); this robot has {', '.join(names)}"
        )
    if robot.urdf is not None:
        found, _ = file_origins(robot)
        origins = [found[n] for n in names]
    else:
        origins = [
            transform(j.xyz, j.rpy) @ _rotation_about(j.axis, j.offset) for j in robot.joints
        ]
    # a calibrated tool is not written (the file ends at wrist_3_link): the check on write
    # measures and states it (`ur_kinematics_contract`)
    return origins, offset_note(robot, "a UR kinematics file")


def ur_kinematics_text(robot) -> tuple[str, list[str]]:
    """The ``kinematics:`` YAML of `robot`, and notes on what it cannot hold."""
    origins, notes = (_urdf_origins if robot.convention == "urdf" else _dh_origins)(robot)
    if robot.convention == "urdf" and any(
        not np.allclose(j.axis, (0, 0, 1), rtol=0, atol=1e-12) for j in robot.joints
    ):
        raise CalibrationError(
            f"robot {robot.name!r}: a UR kinematics file needs joints about their z axes"
        )
    if not _is_identity(transform(robot.base.xyz, robot.base.rpy)):
        notes.append(
            "the base frame (instrument to the base) is not part of the robot and is not "
            "written; save the robot as .toml to keep it"
        )
    if robot.points:
        notes.append("the measured points (reflectors) are not written: the file has no place")
    lines = ["kinematics:"]
    for key, T in zip(KEYS, origins, strict=True):
        xyz, rpy = split(T)
        lines.append(f"  {key}:")
        lines += [f"    {f}: {float(v)!r}" for f, v in zip(FIELDS, (*xyz, *rpy), strict=True)]
    lines.append(f"  hash: casecal_{abs(hash(tuple(np.round(np.ravel(origins), 15)))):x}")
    return "\n".join(lines) + "\n", notes


def _parse(text: str, label: str) -> dict[str, dict[str, float]]:
    """The six origins of a ``kinematics:`` file (the subset of YAML it uses)."""
    groups: dict[str, dict[str, float]] = {}
    current = None
    seen_top = False
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].rstrip()
        if not line.strip():
            continue
        indent = len(line) - len(line.lstrip())
        key, _, value = line.strip().partition(":")
        value = value.strip()
        if indent == 0:
            if key != "kinematics" or value:
                raise CalibrationError(f"{label}: line {number}: expected 'kinematics:'")
            seen_top = True
        elif not seen_top:
            raise CalibrationError(f"{label}: line {number}: expected 'kinematics:' first")
        elif key == "hash":
            continue
        elif not value:
            if key not in KEYS:
                raise CalibrationError(
                    f"{label}: line {number}: {key!r} is not one of {', '.join(KEYS)}"
                )
            current = groups.setdefault(key, {})
        elif current is None or key not in FIELDS:
            raise CalibrationError(f"{label}: line {number}: unexpected {key!r}")
        else:
            try:
                current[key] = float(value)
            except ValueError:
                raise CalibrationError(
                    f"{label}: line {number}: {value!r} is not a number"
                ) from None
    for key in KEYS:
        missing = [f for f in FIELDS if f not in groups.get(key, {})]
        if missing:
            raise CalibrationError(f"{label}: {key} misses {', '.join(missing)}")
    return groups


def read_ur_kinematics(text: str, label: str = "kinematics file", name: str = "ur"):
    """The URDF-convention `Robot` of the six joints a ``kinematics:`` file describes."""
    from .robot import Robot

    groups = _parse(text, label)
    joints = []
    for joint, key, limits in zip(JOINTS, KEYS, LIMITS, strict=True):
        g = groups[key]
        joints.append(
            UrdfJoint(
                name=joint,
                type="R",
                axis=(0.0, 0.0, 1.0),
                xyz=(g["x"], g["y"], g["z"]),
                rpy=(g["roll"], g["pitch"], g["yaw"]),
                limits=limits,
            )
        )
    return Robot(
        name=name,
        joints=tuple(joints),
        convention="urdf",
        full_name=f"{name} (UR kinematics file: base_link_inertia to tool0)",
        source=(label,),
    )


def ur_kinematics_contract(robot, label: str):
    """What a UR kinematics file holds of `robot` (`casecal.model.export_check.Contract`).

    The chain from ``base_link_inertia`` to ``wrist_3_link`` (tool0), compared in the
    robot's base frame: for a DH robot the table without a6, alpha6, beta6 and the tool;
    for a URDF robot its joints, ending at ``wrist_3_link`` followed by the fixed joints its
    own URDF has after ``wrist_3_joint`` (those are ur_description's, not the file's). What
    is beyond is a TCP, which the reason gives for the controller.
    """
    import dataclasses
    from pathlib import Path

    from .export_check import Contract, tcp_text
    from .robot import Frame

    reference = dataclasses.replace(robot, base=Frame(), auto_beta=False)
    geometry = dataclasses.replace(reference, terms=(), auto_beta=False)
    end = Frame()
    if robot.convention == "dh":
        last = robot.joints[-1]
        cut = dataclasses.replace(last, a=0.0, alpha=0.0, beta=None if last.beta is None else 0.0)
        joints = (*robot.joints[:-1], cut)
        wrist = dataclasses.replace(geometry, joints=joints, tool=Frame(), auto_beta=False)
        parts = [f"a6 = {last.a * 1e3:.4g} mm"] if last.a else []
        parts += [f"alpha6 = {math.degrees(last.alpha):.4g}°"] if last.alpha else []
        parts += [f"beta6 = {math.degrees(last.beta):.4g}°"] if last.beta else []
        if not _is_identity(transform(robot.tool.xyz, robot.tool.rpy)):
            parts.append("the tool frame")
        what = " and ".join([", ".join(parts[:-1]), parts[-1]] if len(parts) > 1 else parts)
        lost = f"{what or 'the tool side'} {'has' if len(parts) < 2 else 'have'} no place"
    else:
        if robot.urdf is not None:
            from .urdf_out import file_origins

            nominal = np.eye(4)
            for j in file_origins(robot)[1]:
                nominal = nominal @ j.T
            end = Frame(*split(nominal))
        wrist = dataclasses.replace(geometry, tool=Frame(), auto_beta=False)
        lost = "the calibrated tool frame is not written: it has no place"
    q0 = np.zeros((1, robot.dof))
    tcp = np.linalg.inv(wrist.fk(q0)[0]) @ geometry.fk(q0)[0]
    reason = (
        f"{lost} in a UR kinematics file (tool0 is wrist_3_link); set the controller's TCP "
        f"to {tcp_text(tcp)} to keep it, or save as .toml"
    )

    def read(text: str):
        back = read_ur_kinematics(text, label, Path(label).stem)
        return dataclasses.replace(back, tool=end, points=robot.points, auto_beta=False)

    held = dataclasses.replace(wrist, tool=end, auto_beta=False)
    return Contract("a UR kinematics file", reference, held, read, tool_reason=reason)
