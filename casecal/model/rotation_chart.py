"""Deviations of a frame's rotation without the roll-pitch-yaw singularity at pitch ±90°.

The base and tool frames and every URDF joint origin store their rotation as roll, pitch,
yaw: ``R = Rz(yaw) Ry(pitch) Rx(roll)``. Adding deviations to those three angles cannot turn
the frame every way at pitch ±90° (gimbal lock, common in URDFs: ``rpy="0 1.5708 0"``):
there the yaw turns about the frame's own x axis, as the roll does, and no angle turns it
about the third axis. Near the lock that direction costs angles of order one; a fit
linearised there stalls. casecal therefore defines the deviation ``δ = (δroll, δpitch,
δyaw)`` of a frame whose angles are ``(r0, p0, y0)`` as the rotation::

    R(δ) = Rz(y0) Ry(p0) · Rz(δyaw) Ry(δpitch) · Rx(r0 + δroll)

(`deviate`; `deviation` is its inverse). At ``δ = 0`` its three directions, in the frame's
own axes, are ``x``, ``Rx(-r0) y`` and ``Rx(-r0) z``: orthonormal at any nominal rotation,
so the Jacobian columns of the three never become parallel (`casecal.model.kinematics`
builds the same product, about an anchor, so its columns are exact derivatives in δ).

What that means for a user's deviation:

- where the nominal pitch is 0 (the base and tool frames of most robots, most URDF
  origins), and for any frame whenever ``δyaw = 0``, it is exactly adding δ to the angles,
  as before;
- δroll and δpitch always equal adding to the angles to first order;
- δyaw turns about the z axis of the frame turned by its yaw and pitch, which is the
  parent's z axis only when the pitch is 0: adding Δ to the yaw angle is, to first order,
  ``δyaw = Δ cos p0`` with ``δroll = -Δ sin p0`` (at pitch ±90° a pure roll: the lock).

The robot keeps roll, pitch and yaw as its numbers (`casecal.model.frames.rpy_from_matrix`
writes a deviated rotation back, exact to rounding at the lock too): gimbal lock spoils
derivatives, not values.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from .frames import matrix_from_rpy, rpy_from_matrix


def triples(names) -> list[tuple[str, str, str]]:
    """The (roll, pitch, yaw) names of every rotation among `names`: the base and tool
    frames' ``_rx, _ry, _rz`` (a later session's too: ``base_rx@B``) and each URDF
    origin's ``.roll, .pitch, .yaw``."""
    out = []
    for name in names:
        plain, mark, label = name.partition("@")
        if "." in name:
            if name.endswith(".roll"):
                joint = name[: -len("roll")]
                out.append((name, joint + "pitch", joint + "yaw"))
        elif plain in ("base_rx", "tool_rx"):
            out.append((name, plain[:-1] + "y" + mark + label, plain[:-1] + "z" + mark + label))
    return out


def is_anchored(name: str) -> bool:
    """Whether `name` is the pitch or yaw of a rotation: in the kinematic graph these turn
    relative to an anchor (`casecal.model.kinematics.Chain.extended`)."""
    if "." in name:
        return name.rsplit(".", 1)[1] in ("pitch", "yaw")
    return name.partition("@")[0] in ("base_ry", "base_rz", "tool_ry", "tool_rz")


def _yaw_pitch(rpy0) -> np.ndarray:
    return matrix_from_rpy((0.0, rpy0[1], rpy0[2]))


def deviate(rpy0, delta) -> tuple[float, float, float]:
    """Roll, pitch, yaw (rad) of the rotation `rpy0` deviated by `delta` (module doc).

    Parameters
    ----------
    rpy0, delta : sequence of 3 float
        The nominal (roll, pitch, yaw) and the deviation (δroll, δpitch, δyaw), rad.
    """
    r0, p0, y0 = (float(v) for v in rpy0)
    dr, dp, dy = (float(v) for v in delta)
    if p0 == 0.0 or dy == 0.0:
        # Rz(y0) and Rz(δyaw), or Ry(p0) and Ry(δpitch), are one rotation: adding is exact
        return r0 + dr, p0 + dp, y0 + dy
    R = _yaw_pitch(rpy0) @ matrix_from_rpy((r0 + dr, dp, dy))
    return rpy_from_matrix(R, hint=(r0, p0, y0))


def deviation(rpy0, rpy) -> tuple[float, float, float]:
    """The δ (rad) that `deviate` takes from `rpy0` to the rotation `rpy`: its inverse.

    δpitch is within ±π/2 and δroll within ±π, but where the nominal pitch is 0: there, as
    `deviate` adds, this subtracts.
    """
    r0, p0, _ = (float(v) for v in rpy0)
    if p0 == 0.0:
        return tuple(float(a) - float(b) for a, b in zip(rpy, rpy0, strict=True))
    M = _yaw_pitch(rpy0).T @ matrix_from_rpy(rpy)  # Rz(δyaw) Ry(δpitch) Rx(r0 + δroll)
    roll, dp, dy = rpy_from_matrix(M, hint=(r0, 0.0, 0.0))
    return math.remainder(roll - r0, 2 * math.pi), dp, dy


def deviated(values: Mapping[str, float], deviations: Mapping[str, float]) -> dict:
    """`values` (name → SI value, every parameter) with `deviations` applied: added to
    lengths and lone angles, through `deviate` to rotations. Only the changed names."""
    out = {n: values[n] + float(v) for n, v in deviations.items()}
    for names in triples(values):
        delta = [float(deviations.get(n, 0.0)) for n in names]
        if any(delta):
            out.update(zip(names, deviate([values[n] for n in names], delta), strict=True))
    return out


def deviations_between(
    nominal: Mapping[str, float], values: Mapping[str, float], names=None
) -> dict:
    """The deviations (SI) that take the parameters `nominal` to `values`, for `names`
    (default: all of `nominal`): differences of lengths and lone angles, `deviation` of
    rotations; ``robot(nominal).with_deviations(result)`` is ``robot(values)``."""
    names = list(nominal) if names is None else list(names)
    out = {n: values[n] - nominal[n] for n in names}
    wanted = set(names)
    for triple in triples(nominal):
        if wanted.isdisjoint(triple):
            continue
        delta = deviation([nominal[n] for n in triple], [values[n] for n in triple])
        out.update((n, d) for n, d in zip(triple, delta, strict=True) if n in wanted)
    return out
