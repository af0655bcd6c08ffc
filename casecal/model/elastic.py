"""Lateral (bending) compliance: a joint that tilts under the gravity moment across its axis.

Joint compliance (`casecal.model.terms.compliance`) turns joint i about its own axis by
``c{i}·τ_i``, τ_i the gravity torque about the axis. A light robot's joints also give
across the axis: bearings and links bend under the moment about the two axes
perpendicular to the joint's (DLR's "lateral elasticity", Tenhumberg & Bäuml, Humanoids
2021). Here, per joint i, with M_i the gravity moment about a point p_i on its axis a_i of
the bodies it carries (`gravity_moment`, world frame, N·m):

- ``u_i``: the unit part perpendicular to a_i of one axis of the frame of the body joint i
  moves (x for DH and modified DH frames, whose x is perpendicular to the joint's axis by
  construction; for a URDF joint the child frame's axis least aligned with the joint's
  axis, x on ties), and ``v_i = a_i × u_i``; both turn with the joint;
- everything joint i moves turns about p_i by ``c{i}_u · (M_i·u_i)`` about u_i, then by
  ``c{i}_v · (M_i·v_i)`` about v_i (rad; ``c{i}_u``, ``c{i}_v`` in rad/(N·m)).

As for torsion, the moments are taken on the rigid robot: the deflections' own effect on
them is second order (1e-3 rad of bending moves a 1 kg·m moment by 1e-2 N·m).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..errors import CalibrationError
from .terms import PAYLOAD, ErrorTerm, TermContext, _lateral


def gravity_moment(ctx: TermContext, joint: int, inertials, payload_com=None) -> ca.SX:
    """Gravity's moment about the point on joint `joint`'s (1-based) axis of the bodies it
    carries (`TermContext.beyond`) and of the payload, world frame, N·m, shape (3,).

    `inertials` as for `casecal.model.terms.gravity_torque`; `payload_com` (m, tool
    frame) where the robot reads a payload mass (`casecal.model.terms.PAYLOAD`)."""
    from .masses import body_mass

    i = joint - 1
    moment = ca.SX.zeros(3)
    for k in ctx.beyond(joint):
        inertial = body_mass(ctx, k, inertials)
        if inertial is None:
            continue
        mass, com = inertial
        body = ctx.bodies[k]
        centre = body[:3, :3] @ com + body[:3, 3]
        moment = moment + ca.cross(centre - ctx.points[i], mass * ctx.gravity)
    if payload_com is not None and PAYLOAD in ctx.inputs and ctx.tool is not None:
        centre = ctx.tool[:3, :3] @ ca.DM(payload_com) + ctx.tool[:3, 3]
        moment = moment + ca.cross(centre - ctx.points[i], ctx.inputs[PAYLOAD] * ctx.gravity)
    return moment


def _about(axis: ca.SX, angle: ca.SX) -> ca.SX:
    """The rotation by `angle` (rad) about unit `axis` (Rodrigues), 3 × 3; smooth at 0."""
    K = ca.skew(axis)
    return ca.SX.eye(3) + ca.sin(angle) * K + (1 - ca.cos(angle)) * (K @ K)


def lateral_turn(ctx: TermContext, term: ErrorTerm) -> ca.SX:
    """The bending of joint `term.joint` (module doc) as the transform after its body, in
    the body's frame, 4 × 4."""
    cu, cv = term.parameters
    *inertials, payload_com, pick = term.data
    i = term.joint - 1
    a, p, body = ctx.axes[i], ctx.points[i], ctx.bodies[i]
    moment = gravity_moment(ctx, term.joint, inertials, payload_com)
    b = body[:3, pick]
    u = b - ca.dot(b, a) * a
    u = u / ca.norm_2(u)
    v = ca.cross(a, u)
    D = _about(u, ctx.p(cu) * ca.dot(moment, u)) @ _about(v, ctx.p(cv) * ca.dot(moment, v))
    # the world turn x -> D (x - p) + p, seen from the body's frame: R^T D R, and the
    # body's origin moved by D (t - p) + p - t
    R, t = body[:3, :3], body[:3, 3]
    out = ca.SX.eye(4)
    out[:3, :3] = R.T @ D @ R
    out[:3, 3] = R.T @ (D @ (t - p) + p - t)
    return out


def lateral_compliance(
    joint: int, inertials, pick: int, values=(), payload_com=(0.0, 0.0, 0.0)
) -> ErrorTerm:
    """Joint `joint`'s bending ``c{joint}_u``, ``c{joint}_v`` (rad/(N·m)) under the gravity
    moment of the bodies it carries (module doc); `pick`: the body frame's axis (0, 1, 2)
    whose part perpendicular to the joint's axis is u."""
    data = tuple(None if x is None else (float(x[0]), tuple(map(float, x[1]))) for x in inertials)
    data += (tuple(float(v) for v in payload_com), int(pick))
    names = (f"c{joint}_u", f"c{joint}_v")
    return ErrorTerm("lateral_compliance", joint, names, _lateral, tuple(values), data, "link")


def bending_axis(robot, joint: int) -> int:
    """The axis of joint `joint`'s (1-based) body frame that u is taken from (module doc)."""
    if robot.convention != "urdf":
        return 0
    axis = np.abs(np.asarray(robot.joints[joint - 1].axis, dtype=float))
    return int(np.argmin(axis))  # argmin takes the first of equals: x on ties


def lateral_terms(robot, joints) -> list[ErrorTerm]:
    """Lateral compliance terms of `robot` on `joints` (1-based); its masses needed."""
    if not robot.inertials or all(x is None for x in robot.inertials):
        raise CalibrationError(
            f"robot {robot.name!r}: lateral compliance needs the bodies' masses (inertials, "
            "e.g. from the URDF's <inertial> tags): the bending moments come from them"
        )
    return [
        lateral_compliance(j, robot.inertials, bending_axis(robot, j), (), robot.payload_com)
        for j in joints
    ]
