"""Masses and centres of mass as parameters, where the CAD's are not known well.

A compliance term turns a joint by its compliance times the gravity torque of the bodies
it carries (`casecal.model.terms`, `casecal.model.elastic`), computed from each body's
mass and centre of mass (`Robot.inertials`, the URDF's ``<inertial>`` tags). Where those
are uncertain (a cable harness, a hand the CAD lacks), `Robot.with_masses` makes them
parameters: per body k, ``m{k}`` (kg) and ``m{k}_x``, ``m{k}_y``, ``m{k}_z`` (m, in the
frame of the body joint k moves), starting at the robot's inertials. Every compliance
term then reads them in place of the fixed numbers.

A mass is seen only through what it bends: its columns are zero while the compliances
are, and a compliance times a mass is what the data see, so all masses scaled by s and
all compliances by 1/s fit alike. The identifiability analysis decides what is held, as
for any other parameter; give the compliances their nominal values (or estimate the
masses after a first fit) and keep at least one mass known.
"""

from __future__ import annotations

import casadi as ca

from ..errors import CalibrationError
from .terms import ErrorTerm, TermContext


def _no_turn(ctx: TermContext, term: ErrorTerm) -> ca.SX:
    return ca.SX.eye(4)  # the body's mass moves nothing by itself; compliance reads it


def mass_term(joint: int, mass: float, com) -> ErrorTerm:
    """Body `joint`'s (1-based) mass (kg) and centre of mass (m, its frame) as parameters
    ``m{joint}``, ``m{joint}_x/y/z`` starting at `mass`, `com`."""
    names = (f"m{joint}", f"m{joint}_x", f"m{joint}_y", f"m{joint}_z")
    values = (float(mass), *(float(v) for v in com))
    units = ("kg", "m", "m", "m")
    return ErrorTerm("mass", joint, names, _no_turn, values, (), "link", units=units)


def mass_terms(robot, joints=None) -> list[ErrorTerm]:
    """Mass terms of `robot`'s bodies `joints` (1-based; None: every body with a mass),
    starting at its inertials (a body without one at 0 kg)."""
    inertials = robot.inertials or (None,) * len(robot.joints)
    if joints is None:
        joints = [k for k, x in enumerate(inertials, start=1) if x is not None]
        if not joints:
            raise CalibrationError(
                f"robot {robot.name!r} has no masses to estimate; give its inertials (the "
                "URDF's <inertial> tags), or name the bodies: with_masses([3, 6])"
            )
    bad = [j for j in joints if not (isinstance(j, int) and 1 <= j <= len(robot.joints))]
    if bad:
        raise CalibrationError(f"robot {robot.name!r} has no body {bad[0]!r} (joints 1 … n)")
    return [mass_term(j, *(inertials[j - 1] or (0.0, (0.0, 0.0, 0.0)))) for j in joints]


def body_mass(ctx: TermContext, k: int, inertials):
    """Body `k`'s (0-based) (mass, centre of mass in its frame) for a gravity term: the
    parameters ``m{k+1}``… where the robot has them, else `inertials[k]` (None: none)."""
    name = f"m{k + 1}"
    if name in ctx.names:
        return ctx.p(name), ca.vertcat(*(ctx.p(f"{name}_{a}") for a in "xyz"))
    if inertials[k] is None:
        return None
    mass, com = inertials[k]
    return mass, ca.DM(com)
