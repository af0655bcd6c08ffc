"""The symbolic walk down a serial chain, base to flange, for every convention.

Besides the flange pose it returns what error terms built on the rigid chain need (joint
gravity torques): each joint's axis and a point on it, and the frame of the body each
joint moves, all in the world frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca


@dataclass(frozen=True)
class Walk:
    """A chain walked once: the flange pose and, per joint, its axis and the body it moves.

    Attributes
    ----------
    T : SX, 4 × 4
        World pose of the last link's frame (before the tool frame).
    axes, points : list of SX, 3 each
        Joint i's unit axis and a point on it, world frame.
    bodies : list of SX, 4 × 4
        World pose of the frame of the body joint i moves (DH frame i, URDF child link).
    """

    T: ca.SX
    axes: list
    points: list
    bodies: list


def walk(structure, base: ca.SX, q_eff, P: dict, trig: dict, after=None, joint_trig=None) -> Walk:
    """Walk `structure` from `base` with effective joint variables `q_eff` (list of SX);
    `after[i]`, when given and not None, is applied after joint i's link; `joint_trig[i]`,
    when given and not None, is (cos, sin) of revolute joint i's angle (offset included)."""
    from .kinematics import link_transform

    T, axes, points, bodies = base, [], [], []
    after = after or [None] * len(q_eff)
    joint_trig = joint_trig or [None] * len(q_eff)
    if structure.convention == "urdf":
        for jt, name, axis, q, before in _urdf_rows(structure, q_eff):
            origin, T = _urdf_joint(
                T, (jt, name, axis, q, before), q_eff, P, trig, joint_trig[len(bodies)]
            )
            axes.append(origin[:3, :3] @ ca.DM(axis))
            points.append(origin[:3, 3])
            T = T if after[len(bodies)] is None else T @ after[len(bodies)]
            bodies.append(T)
        return Walk(T, axes, points, bodies)
    for i, (jt, q) in enumerate(zip(structure.joint_types, q_eff, strict=True), start=1):
        link = link_transform(
            structure.convention,
            jt,
            q,
            P[f"theta{i}"],
            P[f"d{i}"],
            P[f"a{i}"],
            trig[f"alpha{i}"],
            trig.get(f"beta{i}"),
            joint_trig[i - 1],
        )
        link_after = T @ link
        # standard DH turns link i about z of frame i-1; modified DH about z of frame i
        on = T if structure.convention == "dh" else link_after
        axes.append(on[:3, 2])
        points.append(on[:3, 3])
        T = link_after if after[i - 1] is None else link_after @ after[i - 1]
        bodies.append(T)
    return Walk(T, axes, points, bodies)


def _urdf_joint(T, joint, q_eff, P: dict, trig: dict, cs=None):
    """One actuated URDF joint walked from the frame `T` it hangs from: its mimic joints,
    then its origin and motion. `joint` is (type, name, axis, q, mimic joints before it);
    `cs` as `walk`'s `joint_trig[i]`. Returns (its origin, the frame it moves)."""
    from .kinematics import frame_transform, joint_motion, rotation_trig

    jt, name, axis, q, before = joint
    for p_name, p_type, p_axis, master, multiplier, offset in before:
        xyz = [P[f"{p_name}.{c}"] for c in "xyz"]
        rpy = rotation_trig(trig, [f"{p_name}.{c}" for c in ("roll", "pitch", "yaw")])
        T = T @ frame_transform(xyz, rpy)
        T = T @ joint_motion(p_type, p_axis, multiplier * q_eff[master] + offset)
    xyz = [P[f"{name}.{c}"] for c in "xyz"]
    origin = T @ frame_transform(
        xyz, rotation_trig(trig, [f"{name}.{c}" for c in ("roll", "pitch", "yaw")])
    )
    angle = q + P[f"{name}.offset"] if jt == "R" else q
    return origin, origin @ joint_motion(jt, axis, angle, cs)


def walk_tree(structure, base: ca.SX, q_eff, P: dict, trig: dict, joint_trig=None, after=None):
    """A tree walked once: its tips' world poses and, per joint, what `walk` gives.

    Each joint is walked from the frame of the joint it hangs from (`structure.parents`;
    the base for -1), so a path the tips share is one piece of the graph: ``T_joint =
    T_parent · origin · motion [· after]`` and ``T_tip = T_parent · tip frame``.

    Returns
    -------
    tips : list of SX, 4 × 4
        World pose of each tip (`structure.tips`' order).
    Walk
        `T` is the base; `axes`, `points`, `bodies` per joint, as `walk`'s.
    """
    from .kinematics import frame_transform, rotation_trig

    joint_trig = joint_trig or [None] * len(q_eff)
    after = after or [None] * len(q_eff)
    moved, axes, points = [], [], []  # per joint: the frame it moves, its axis, a point
    for i, joint in enumerate(_urdf_rows(structure, q_eff)):
        parent = structure.parents[i]
        T = base if parent < 0 else moved[parent]
        origin, T = _urdf_joint(T, joint, q_eff, P, trig, joint_trig[i])
        axes.append(origin[:3, :3] @ ca.DM(joint[2]))
        points.append(origin[:3, 3])
        moved.append(T if after[i] is None else T @ after[i])
    tips = []
    for name, parent in structure.tips:
        xyz = [P[f"{name}.{c}"] for c in "xyz"]
        rpy = rotation_trig(trig, [f"{name}.{c}" for c in ("roll", "pitch", "yaw")])
        tips.append((base if parent < 0 else moved[parent]) @ frame_transform(xyz, rpy))
    return tips, Walk(base, axes, points, moved)


def carried(parents) -> tuple[tuple[int, ...], ...]:
    """Per joint, the 0-based joints whose bodies it carries (itself and every joint below
    it), for a tree given by `parents` (each joint's parent index, -1 the base; parents
    come first). A serial chain's joint i carries i … n-1."""
    below: list[list[int]] = [[i] for i in range(len(parents))]
    for i in reversed(range(len(parents))):  # children come after their parents
        if parents[i] >= 0:
            below[parents[i]] += below[i]
    return tuple(tuple(sorted(b)) for b in below)


def _urdf_rows(structure, q_eff):
    """Per URDF joint: (type, name, axis, q, the mimic joints walked before it)."""
    passive = structure.passive or ((),) * len(q_eff)
    return zip(
        structure.joint_types, structure.joint_names, structure.axes, q_eff, passive, strict=True
    )
