"""Pose schedules: the paper's lockstep schedule and uniform samples inside the joint limits."""

from __future__ import annotations

import numpy as np

from ..errors import CalibrationError
from ..model.robot import Robot

MAX_POSES = 10_000_000
"""More poses than anyone measures; beyond it a request is a typo, not a plan."""


def _check_count(n) -> int:
    if isinstance(n, bool) or not isinstance(n, int | np.integer) or not 1 <= n <= MAX_POSES:
        raise CalibrationError(
            f"number of poses must be a positive integer (at most {MAX_POSES:,}), got {n!r}"
        )
    return int(n)


def rng_from(seed) -> np.random.Generator:
    """A numpy Generator from a seed (non-negative int), a Generator, or None."""
    if isinstance(seed, int | np.integer) and not isinstance(seed, bool) and seed < 0:
        raise CalibrationError(f"a seed must be a non-negative integer, got {seed}")
    try:
        return np.random.default_rng(seed)
    except (TypeError, ValueError):
        raise CalibrationError(f"a seed must be a non-negative integer, got {seed!r}") from None


def seed_schedule(robot: Robot, n: int) -> np.ndarray:
    """The schedule of Simpson & Hayes: every joint moves together in equal steps.

    Pose ``k = 0 … n-1`` sets every revolute joint to ``q = k°`` (so the first pose is the
    zero configuration and the last is ``(n-1)°``), and every prismatic joint to
    ``lower + k / (n-1) · (upper - lower)``, from its lower limit to full extension (its
    lower limit when n = 1). As in the paper, revolute joint limits are not applied: at 100
    poses some joints of some robots leave their range.

    Parameters
    ----------
    robot : Robot
    n : int
        Number of poses.

    Returns
    -------
    q : ndarray, shape (n, dof)
        Joint values, rad (R) or m (P).
    """
    n = _check_count(n)
    k = np.arange(n, dtype=float)
    q = np.empty((n, robot.dof))
    for i, joint in enumerate(robot.controller_joints):
        if joint.type == "R":
            q[:, i] = np.deg2rad(k)
        else:
            lo, hi = robot.limits[i]
            q[:, i] = lo + (hi - lo) * (k / (n - 1) if n > 1 else 0.0)
    return q


def uniform(robot: Robot, n: int, seed=None) -> np.ndarray:
    """Poses drawn uniformly inside the joint limits.

    Parameters
    ----------
    robot : Robot
        Its `Robot.limits` are used (±180° for revolute joints without limits); a coupled
        robot's model (`Robot.uncoupled`) is drawn through its controller joints.
    n : int
        Number of poses.
    seed : int, numpy Generator or None
        Randomness; give an int for a reproducible schedule.

    Returns
    -------
    q : ndarray, shape (n, dof)
        Joint values, rad (R) or m (P).
    """
    n = _check_count(n)
    rng = rng_from(seed)
    if robot.coupled_from is not None:  # a coupled robot's model: the poses it can take
        coupled = robot.coupled_from
        return coupled.model_joints(uniform(coupled, n, rng))[:, : robot.dof]
    limits = robot.limits
    return rng.uniform(limits[:, 0], limits[:, 1], size=(n, robot.dof))


def optimal(
    robot: Robot,
    n: int,
    candidates=None,
    criterion: str = "O1",
    parameters=None,
    seed=0,
    n_candidates: int = 2000,
    max_passes: int = 10,
    include=None,
) -> np.ndarray:
    """Choose `n` poses from candidates that maximise an observability index.

    The identification Jacobian of each candidate (3 × k, columns scaled by their norms
    over all candidates) adds ``JᵀJ`` to the information matrix M. ``"O1"`` maximises
    ``log det M`` (D-optimal: O1 is its geometric mean of singular values); ``"O3"`` its
    smallest eigenvalue (E-optimal). A greedy pass adds the best candidate at each step,
    then exchange passes (DETMAX) swap chosen poses for better candidates until no swap
    improves the criterion. Each candidate is scored by rank-3 updates (Woodbury and the
    matrix determinant lemma), not by refactorising M.

    Parameters
    ----------
    robot : Robot
    n : int
        Number of poses to choose.
    candidates : array-like, shape (C, dof), optional
        Default: `n_candidates` uniform poses inside the limits (`seed`).
    criterion : {"O1", "O3"}
    parameters : optional
        The parameters the poses should identify (default: the paper's θ, a, d), reduced
        to those the candidates can identify at all.
    seed : int
    n_candidates : int
    max_passes : int
        Exchange passes at most.
    include : array-like, shape (m, dof), optional
        Poses already measured: their information counts, and the `n` new poses complete
        them (sequential design). They are not returned.

    Returns
    -------
    q : ndarray, shape (n, dof)
        The chosen poses, in the order chosen.
    """
    from ..identification.analysis import analyse, selection  # poses sit below identification

    n = _check_count(n)
    if criterion not in ("O1", "O3"):
        raise CalibrationError(f"criterion must be 'O1' or 'O3', got {criterion!r}")
    cand = (
        uniform(robot, n_candidates, seed=seed)
        if candidates is None
        else np.asarray(candidates, float)
    )
    if cand.ndim != 2 or cand.shape[1] != robot.dof or len(cand) < n:
        raise CalibrationError(f"candidates must be (C, {robot.dof}) with C >= n = {n}")
    names = selection(robot, parameters)
    J, names = robot.position_jacobian(cand, names, deviations=True)  # what a fit estimates
    base = analyse(J.reshape(-1, len(names)), names, len(cand)).base_parameters
    J = J[:, :, [names.index(b) for b in base]]
    scale = np.linalg.norm(J.reshape(-1, len(base)), axis=0)
    J = J / scale  # (C, 3, k) scaled
    k, rows = len(base), J.shape[1]  # rows: 3 per pose, per tip of a tree
    if rows * (n + (0 if include is None else len(include))) < k:
        give = "poses give" if n != 1 else "pose gives"
        raise CalibrationError(f"{n} {give} {rows * n} coordinates for {k} parameters")
    M0 = None
    if include is not None and len(include):
        Ji, _ = robot.position_jacobian(np.asarray(include, float), names, deviations=True)
        Ji = Ji[:, :, [names.index(b) for b in base]] / scale
        M0 = np.einsum("cik,cil->kl", Ji, Ji)
    chosen = _greedy(J, n, criterion, M0)
    chosen = _exchange(J, chosen, criterion, max_passes, M0)
    return cand[chosen]


def _score(J: np.ndarray, Minv: np.ndarray, M: np.ndarray, criterion: str) -> np.ndarray:
    """Criterion gain of adding each candidate's rows J (C, 3, k) to M (a tree's: 3 per
    tip)."""
    if criterion == "O1":
        A = (J @ Minv) @ np.swapaxes(J, 1, 2) + np.eye(J.shape[1])  # (C, 3, 3), batched
        return np.linalg.slogdet(A)[1]
    # O3: first-order gain along the weakest direction, then exact on the best few
    w, V = np.linalg.eigh(M)
    v = V[:, 0]
    first = np.sum((J @ v) ** 2, axis=1)
    best = np.argsort(first)[-16:]
    gain = np.full(len(J), -np.inf)
    for c in best:
        gain[c] = np.linalg.eigvalsh(M + J[c].T @ J[c])[0] - w[0]
    return gain


def _greedy(J: np.ndarray, n: int, criterion: str, M0=None) -> list[int]:
    k = J.shape[2]
    eps = 1e-9 * np.trace(np.einsum("cik,cil->kl", J, J)) / len(J)
    M = eps * np.eye(k) + (0 if M0 is None else M0)  # a tiny ridge: invertible from the start
    Minv = np.linalg.inv(M)
    chosen: list[int] = []
    available = np.ones(len(J), bool)
    for _ in range(n):
        gain = _score(J, Minv, M, criterion)
        gain[~available] = -np.inf
        c = int(np.argmax(gain))
        chosen.append(c)
        available[c] = False
        M += J[c].T @ J[c]
        Minv = _woodbury(Minv, J[c], +1.0)
    return chosen


def _woodbury(Minv: np.ndarray, Jc: np.ndarray, sign: float) -> np.ndarray:
    """(M ± Jcᵀ Jc)⁻¹ from M⁻¹ by the Woodbury identity (rank 3, or 3 per tip)."""
    U = Minv @ Jc.T  # (k, 3)
    S = np.eye(len(Jc)) * sign + Jc @ U
    return Minv - U @ np.linalg.solve(S, U.T)


def _value(M: np.ndarray, criterion: str) -> float:
    if criterion == "O1":
        return float(np.linalg.slogdet(M)[1])
    return float(np.linalg.eigvalsh(M)[0])


def _exchange(
    J: np.ndarray, chosen: list[int], criterion: str, max_passes: int, M0=None
) -> list[int]:
    Jc = J[chosen].reshape(-1, J.shape[2])
    M = Jc.T @ Jc + (0 if M0 is None else M0)
    current = _value(M, criterion)
    for _ in range(max_passes):
        improved = False
        for slot in range(len(chosen)):
            out = chosen[slot]
            M_minus = M - J[out].T @ J[out]
            try:  # positive definite without this pose? then it can be exchanged
                L = np.linalg.cholesky(M_minus)
            except np.linalg.LinAlgError:
                continue
            Linv = np.linalg.inv(L)
            Minv = Linv.T @ Linv
            gain = _score(J, Minv, M_minus, criterion)
            gain[chosen] = -np.inf
            c = int(np.argmax(gain))
            M_new = M_minus + J[c].T @ J[c]
            value = _value(M_new, criterion)
            if value > current + 1e-9 * max(1.0, abs(current)):
                chosen[slot], M, current, improved = c, M_new, value, True
        if not improved:
            break
    return chosen
