"""Pose schedules: the paper's lockstep schedule and uniform samples inside the joint limits."""

from __future__ import annotations

import numpy as np

from .errors import CalibrationError
from .robot import Robot

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
    for i, joint in enumerate(robot.joints):
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
        Its `Robot.limits` are used (±180° for revolute joints without limits).
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
    limits = robot.limits
    return rng.uniform(limits[:, 0], limits[:, 1], size=(n, robot.dof))
