"""A lack-of-fit test that needs no σ and no near neighbours.

Without a stated σ the residuals are taken for noise when they are small enough for an
instrument (`casecal.identification.audit.PLAUSIBLE_NOISE`) and do not change smoothly
from one pose to its nearest neighbour (`casecal.identification.audit.smoothness`). Poses
far apart in joint space have no near neighbour, and a rigid model of an arm that bends
0.02–0.11° under gravity passed with 0.1–0.5 mm residuals while its held-out error was
3–4× what its covariance predicted.

Noise is independent of the joint values; a model error is a smooth function of them. So
the residuals are regressed on generic smooth joint errors (on each joint, sine and
cosine of its angle and of its sums with its neighbours', `joint_functions`, mapped to
the measured points by the joint Jacobian), beside the estimated parameters' columns,
and the decrease of the residual sum of squares is judged by an F test
(`casecal.identification.rank.held_matter`): noise lowers it by no more than chance
allows, a missing term (compliance, joint-angle harmonics, a parameter not asked for) by
far more.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .linalg import Reduction
from .problem import Problem

MOST_POSES = 2000
"""Poses the test looks at (a fixed random subset beyond): enough for a few dozen columns."""


@dataclass(frozen=True)
class LackOfFit:
    """What the smooth basis explains beyond the estimated parameters.

    Attributes
    ----------
    gain : float
        Decrease of ``0.5 Σ r²`` (the cost's units) the basis adds to the estimates'.
    n_extra : int
        Independent directions the basis adds: the degrees of freedom of the gain.
    cost, dof : float, int
        ``0.5 Σ r²`` less what the estimates' own step would remove, and the residual
        degrees of freedom, of the position rows of the looked-at poses.
    """

    gain: float
    n_extra: int
    cost: float
    dof: int


def joint_functions(q: np.ndarray, joint_types: str) -> list[tuple[int, np.ndarray]]:
    """Smooth joint errors to look for, as (joint, values (N,)) pairs: on each joint, the
    sine and cosine of its angle and of its sums with its neighbours' (the gravity
    torque about a pitch joint follows the sum of the pitch angles before it); a
    prismatic joint's value and square, scaled to the range it spans."""
    out = []
    n = len(joint_types)
    for j, kind in enumerate(joint_types):
        if kind == "P":
            z = q[:, j] - q[:, j].mean()
            z = z / (np.ptp(z) or 1.0)
            out += [(j, z), (j, z**2)]
            continue
        angles = [q[:, j]]
        neighbours = [k for k in (j - 1, j + 1) if 0 <= k < n and joint_types[k] == "R"]
        angles += [q[:, j] + q[:, k] for k in neighbours]
        out += [(j, f(a)) for a in angles for f in (np.sin, np.cos)]
    return out


def lack_of_fit(problem: Problem, joint_types: str, poses=None, seed: int = 0) -> LackOfFit | None:
    """`LackOfFit` of `problem` (the estimated parameters at the fitted robot).

    Only the position rows are judged: without a σ, orientation rows carry an arbitrary
    weight (1 mrad like 0.1 mm), and pooling two noise scales in one F test raises false
    alarms where orientations are noisier than that and hides model errors where they are
    not.

    Parameters
    ----------
    problem : Problem
    joint_types : str
    poses : array of int, optional
        The poses to judge (a robust fit's inliers); default all, at most `MOST_POSES`
        of them (a fixed random subset, `seed`).

    Returns None when too few rows are left to judge by (fewer than twice the basis's
    columns past the parameters').
    """
    poses = np.arange(problem.q.shape[0]) if poses is None else np.asarray(poses)
    if len(poses) > MOST_POSES:
        poses = np.sort(np.random.default_rng(seed).choice(poses, MOST_POSES, replace=False))
    if len(poses) < problem.q.shape[0]:
        problem = problem.subset(poses)
    x0 = np.zeros(len(problem.names))
    n, rows, points = len(problem.q), problem.w_rows.shape[1], 3 * problem.m
    J = np.zeros((n * points, 0))
    if problem.names:
        J = problem.jacobian(x0).reshape(n, rows, -1)[:, :points].reshape(n * points, -1)
    r = problem.residual(x0).reshape(n, rows)[:, :points].ravel()
    X = _columns(problem, joint_types)
    (inside, rank_in), (both, rank_both) = _explained(J, X, r)
    n_extra = rank_both - rank_in
    # rows of coordinates not measured (weight 0: a plane's x, y) are no observations
    observed = int(np.count_nonzero(problem.w_rows[:, :points]))
    dof = observed - rank_both
    if n_extra <= 0 or dof < 2 * n_extra:
        return None
    # what the estimates' own (linearised) step leaves: the fit's cost, to rounding
    cost = 0.5 * float(r @ r) - 0.5 * inside
    return LackOfFit(max(0.5 * (both - inside), 0.0), n_extra, cost, observed - rank_in)


def _explained(J: np.ndarray, X: np.ndarray, r: np.ndarray) -> list[tuple[float, int]]:
    """|P_A r|² and the rank of A, for A = J and for A = [J X] (each column scaled to unit
    norm, zero columns left out).

    One QR reduction of [J X] and r answers both: the leading columns of R are the R
    factor of J alone (scaled after the factorisation, as accurate as before it: see
    `Reduction`), and Qᵀr is kept, so |P_A r|² is |U_Rᵀ Qᵀr|² over the left singular
    vectors of A's columns of R that pass the cut. Two thin SVDs of the tall matrices
    cost 2-3× more at a thousand poses.
    """
    red = Reduction.of_blocks((J, X), r)
    norms = np.linalg.norm(red.R, axis=0)  # J's and X's (an exact 0 stays 0 in QR)
    out = []
    for k in (J.shape[1], J.shape[1] + X.shape[1]):
        seen = np.flatnonzero(norms[:k] > 0)
        if seen.size == 0:
            out.append((0.0, 0))
            continue
        U, s, _ = np.linalg.svd(red.R[:, seen] / norms[seen], full_matrices=False)
        rank = int(np.sum(s > s[0] * 1e-9))
        c = U[:, :rank].T @ red.Qtr
        out.append((float(c @ c), rank))
    return out


def _columns(problem: Problem, joint_types: str, h: float = 1e-6) -> np.ndarray:
    """The weighted effect on the measured points of each joint error of
    `joint_functions`, shape (N · 3m, B)."""
    q = problem.q
    n, dof, points = len(q), len(joint_types), 3 * problem.m
    moved = np.empty((n, points, dof))
    # ∂(measured points)/∂q_j by forward differences: the basis is a generic smooth error,
    # and a column off by 1e-6 of itself moves no projection the F test could notice
    here = problem.model_at(q)
    for j in range(dof):
        step = np.zeros(q.shape[1])
        step[j] = h
        moved[:, :, j] = (problem.model_at(q + step) - here) / h
    functions = joint_functions(q[:, :dof], joint_types)
    X = np.stack([moved[:, :, j] * values[:, None] for j, values in functions], axis=2)
    return (X * problem.w_rows[:, :points, None]).reshape(n * points, -1)
