"""Lumped gravity terms without their exact redundancy: a subset of the names that spans
what the full set spans (the "base parameters" of the lumped compliance).

Joint j's lumped deflection (`casecal.model.terms.lumped_compliance`) is linear in 4 terms
per body beyond it, ``Δ_j(q) = Σ_i g_i · φ_i(q)``, but its regressor columns φ_i are not
independent: the torque about joint j is a trigonometric polynomial in the joints beyond
it, and the lumped terms enter it only through fewer combinations, as a robot's masses
enter its gravity torques only through the base parameters of its dynamics (Khalil and
Dombre, *Modeling, Identification and Control of Robots*, 2002, ch. 12; e.g. a body's
mass at a point fixed in the body before it acts as that body's first moment, and a
first moment along the joint's own axis has no lever about it). On the catalog arms
tried (`REDUNDANT`) half are independent: 10 of 20 for joint 2, 8 of 16 for joint 3, 6 of
12 and 4 of 8 for joints 4 and 5. Only the span of the φ_i can be determined by any data,
so a term whose column is a combination of the others' is dropped: the model is the same
function of the joints, with fewer names, and the fit of the kept set equals the full
set's on any data.

The span is found numerically: the columns are sampled at random poses within the limits
(`REDUNDANT` says why that decides the rank) and kept in name order, nearest body first
and ``m, x, y, z`` within a body, when they add a direction to those kept before. The kept
names keep their meaning: a kept term carries its own quantity plus the combinations of
the dropped terms that alias onto it.
"""

from __future__ import annotations

import dataclasses
import re

import casadi as ca
import numpy as np

from ..errors import CalibrationError
from .terms import STANDARD_GRAVITY, ErrorTerm, compliance_terms

KIND = "lumped_compliance_subset"
"""The kind of a lumped term with some of its names left out (`lumped_subset`)."""

REDUNDANT = 1e-7
"""A column (scaled to unit norm) whose part outside the span of the columns kept before it
is below this is a combination of them. Measured on ten catalog arms (rx90b, rx90b_mdh,
kr15_2, kr16_2, kr5_arc, puma560, ur5e, irb120, irb140, lrmate200id) at 256 random poses:
an exact dependency leaves at most 4e-15 (rounding of sums of products of cosines), an
independent column at least 0.04; the cut sits in that gap, many orders from either side.
The singular values of the scaled columns show the same gap (at most 7e-16 against at
least 0.4), so the count kept is the numerical rank."""

ZERO = 1e-9
"""A column below this fraction of the joint's largest is zero (a centre of mass on the
joint's own axis): rounding, not a direction."""

NAME = re.compile(r"^g(\d+)_(\d+)([mxyz])$")
"""A lumped term's name: joint, body, and m or an axis."""


def _lumped_subset(ctx, term: ErrorTerm) -> ca.SX:
    """`casecal.model.terms._lumped` with the names not in ``term.parameters`` at zero."""
    i = term.joint - 1
    own = set(term.parameters)

    def p(name: str):
        return ctx.p(name) if name in own else ca.SX(0)

    down = ctx.gravity / STANDARD_GRAVITY
    total = ca.SX(0)
    for k in range(i, len(ctx.bodies)):
        body = ctx.bodies[k]
        names = [f"g{term.joint}_{k + 1}{a}" for a in "xyz"]
        if not own.intersection(names) and f"g{term.joint}_{k + 1}m" not in own:
            continue
        moment = body[:3, :3] @ ca.vertcat(*(p(n) for n in names))
        arm = (body[:3, 3] - ctx.points[i]) * p(f"g{term.joint}_{k + 1}m")
        total = total + ca.dot(ca.cross(moment + arm, down), ctx.axes[i])
    return total


def lumped_subset(joint: int, n_joints: int, names, values=()) -> ErrorTerm:
    """Joint `joint`'s lumped deflection with only the terms `names` (``g{joint}_{k}m/x/y/z``,
    k ≥ `joint`); the others are held at zero.

    Parameters
    ----------
    joint : int
        1-based.
    n_joints : int
        The robot's model joints.
    names : sequence of str
        Lumped names of this joint, kept in the order given.
    values : sequence of float, optional
        Their values, SI (rad/m for ``m``, rad for ``x/y/z``); zeros by default.

    Returns
    -------
    ErrorTerm
    """
    names = tuple(names)
    if not names:
        raise CalibrationError(f"lumped terms of joint {joint}: give at least one name")
    for name in names:
        match = NAME.match(name)
        if not match or int(match[1]) != joint or not joint <= int(match[2]) <= n_joints:
            raise CalibrationError(
                f"{name!r} is not a lumped gravity term of joint {joint} on a robot of "
                f"{n_joints} joints; they read g{joint}_<body {joint}..{n_joints}><m|x|y|z>"
            )
    if len(set(names)) != len(names):
        raise CalibrationError(f"lumped terms of joint {joint}: a name is given twice")
    return ErrorTerm(KIND, joint, names, _lumped_subset, tuple(values), (n_joints,))


def lumped_regressor(robot, terms, q) -> list[np.ndarray]:
    """Per term, its columns ``∂Δ_j/∂g`` at poses `q`: shape (N, k), rad per unit term.

    A lumped term turns the tool about joint j's axis z_j by ``Δ_j``, so its column of the
    tool's orientation Jacobian is ``z_j ∂Δ_j/∂g`` exactly; projecting on z_j reads it.
    `robot` is a model robot (uncoupled) without the terms; `q` its model joints (N, n).
    """
    from . import kinematics

    probe = robot.with_terms(*terms)
    chain = kinematics.chain(probe.structure)
    p = probe.vector()
    axes = chain.evaluate("joint_jacobian", q, p)[:, 3:, :]  # (N, 3, n): z_j per joint
    out = []
    for t in terms:
        J = chain.evaluate("pose_jacobian", q, p, chain.columns(t.parameters))[:, 3:, :]
        out.append(np.einsum("na,nak->nk", axes[:, :, t.joint - 1], J))
    return out


def independent(columns: np.ndarray) -> list[int]:
    """Indices of the columns of `columns` (N, k) kept in order when each adds a direction
    (`REDUNDANT`) to those kept before it; zero columns (`ZERO`) are never kept."""
    norms = np.linalg.norm(columns, axis=0)
    largest = norms.max(initial=0.0)
    basis = np.zeros((columns.shape[0], 0))
    kept = []
    for k in range(columns.shape[1]):
        if norms[k] <= ZERO * largest or largest == 0.0:
            continue
        c = columns[:, k] / norms[k]
        for _ in range(2):  # twice: one Gram-Schmidt pass loses orthogonality to rounding
            c = c - basis @ (basis.T @ c)
        if np.linalg.norm(c) > REDUNDANT:
            kept.append(k)
            basis = np.column_stack([basis, c / np.linalg.norm(c)])
    return kept


def reduced_lumped_terms(robot, joints=None, n_poses: int | None = None, seed: int = 0):
    """`robot`'s lumped gravity terms on `joints` without the exactly redundant ones.

    Parameters
    ----------
    robot : Robot
        A chain (not a tree); its masses, if any, are not used.
    joints : sequence of int, optional
        1-based revolute joints; None: those that carry gravity load
        (`casecal.model.terms.compliance_terms`).
    n_poses : int, optional
        Poses within the limits at which the columns are sampled; default four times the
        largest number of terms of a joint, at least 256.
    seed : int
        Of the poses.

    Returns
    -------
    list of ErrorTerm
        One `lumped_subset` per joint with a term left, for `Robot.with_terms`; the model
        is the same function of the joints as the full lumped set's.
    """
    full = compliance_terms(robot, joints, lumped=True)
    if not full:
        return []
    # the columns are the lumped terms' own, whatever terms the robot carries already
    model = dataclasses.replace(robot.uncoupled(), terms=(), auto_beta=False)
    n = len(model.joints)
    k = max(len(t.parameters) for t in full)
    n_poses = max(256, 4 * k) if n_poses is None else int(n_poses)
    if n_poses < k:
        raise CalibrationError(f"n_poses must be at least {k}, the terms of one joint")
    lo, hi = model.limits.T
    q = lo + (hi - lo) * np.random.default_rng(seed).random((n_poses, n))
    out = []
    for t, columns in zip(full, lumped_regressor(model, full, q), strict=True):
        kept = [t.parameters[i] for i in independent(columns)]
        if kept:
            out.append(lumped_subset(t.joint, n, kept))
    return out
