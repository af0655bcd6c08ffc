"""Joint rows rebuilt from a parameter vector (by name), for every convention."""

from __future__ import annotations

import dataclasses


def joints_from(robot, p: dict) -> tuple:
    """`robot`'s joints with the values of `p` (name → SI value, every parameter)."""
    joints = []
    for i, j in enumerate(robot.joints, start=1):
        if robot.convention == "urdf":
            passive = tuple(
                dataclasses.replace(
                    m,
                    xyz=tuple(p[f"{m.name}.{c}"] for c in "xyz"),
                    rpy=tuple(p[f"{m.name}.{c}"] for c in ("roll", "pitch", "yaw")),
                )
                for m in j.passive
            )
            joints.append(
                dataclasses.replace(
                    j,
                    passive=passive,
                    xyz=tuple(p[f"{j.name}.{c}"] for c in "xyz"),
                    rpy=tuple(p[f"{j.name}.{c}"] for c in ("roll", "pitch", "yaw")),
                    offset=p[f"{j.name}.offset"] if j.type == "R" else 0.0,
                )
            )
            continue
        joints.append(
            dataclasses.replace(
                j,
                theta=p[f"theta{i}"],
                d=p[f"d{i}"],
                a=p[f"a{i}"],
                alpha=p[f"alpha{i}"],
                beta=p[f"beta{i}"] if j.beta is not None else None,
            )
        )
    return tuple(joints)
