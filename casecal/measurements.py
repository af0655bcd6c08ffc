"""Measurements of a robot's tool point, and their simulation from a 'true' robot."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import CalibrationError
from .robot import Robot, check_joint_values


def broadcast_sigma(sigma, n: int) -> np.ndarray:
    """Noise σ as an (n, 3) array, m.

    Accepts a scalar (every coordinate), 3 values (per axis x, y, z), n values (per pose,
    isotropic; with n = 3 three values are read per axis) or an (n, 3) array.
    """
    try:
        arr = np.asarray(sigma, dtype=float)
        if arr.ndim == 1 and arr.size == n and arr.size != 3:
            arr = arr[:, None]
        out = np.broadcast_to(arr, (n, 3)).copy()
    except (TypeError, ValueError):
        raise CalibrationError(
            f"noise sigma {sigma!r} does not fit {n} poses; give a number, 3 values (x, y, z), "
            "one per pose or (N, 3), in m"
        ) from None
    if not np.all(np.isfinite(out)) or np.any(out < 0):
        raise CalibrationError("noise sigma must be finite and non-negative (m)")
    return out


@dataclass(frozen=True)
class Measurements:
    """Joint readings and the measured tool-point positions at those poses.

    Attributes
    ----------
    q : ndarray, shape (N, dof)
        Joint values, rad (R) or m (P).
    positions : ndarray, shape (N, 3)
        Measured tool-point positions in the world frame, m.
    sigma : ndarray, shape (N, 3)
        Standard deviation of the measurement noise of each coordinate, m; a scalar or
        (3,) per-axis value given to the constructor is broadcast. Zero means noise-free
        (simulated) data or unknown noise.
    kind : str
        ``"position"``.
    """

    q: np.ndarray
    positions: np.ndarray
    sigma: np.ndarray
    kind: str = "position"

    def __post_init__(self) -> None:
        q, _ = check_joint_values(self.q, np.shape(self.q)[-1] if np.ndim(self.q) else 0)
        try:
            y = np.atleast_2d(np.asarray(self.positions, dtype=float))
        except (TypeError, ValueError):
            raise CalibrationError("measured positions are not numbers") from None
        if y.shape != (q.shape[0], 3):
            raise CalibrationError(
                f"measured positions have shape {y.shape}; expected ({q.shape[0]}, 3), "
                "one x, y, z row per pose"
            )
        if not np.all(np.isfinite(y)):
            raise CalibrationError("measured positions contain NaN or inf; remove those rows")
        sigma = broadcast_sigma(self.sigma, q.shape[0])
        for name, value in (("q", q), ("positions", y), ("sigma", sigma)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n_poses(self) -> int:
        """Number of poses N."""
        return self.q.shape[0]


def simulate(true_robot: Robot, q, noise=0.0, seed=None) -> Measurements:
    """Position measurements of `true_robot` at poses `q`, with isotropic Gaussian noise.

    Parameters
    ----------
    true_robot : Robot
        The robot as it really is (e.g. ``nominal.with_deviations({...})``).
    q : array-like, shape (N, dof)
        Joint values, rad (R) or m (P).
    noise : float or array-like of 3 floats
        Standard deviation of the noise on each coordinate, m (e.g. ``0.01e-3`` for
        0.01 mm). Default 0: exact positions.
    seed : int, numpy Generator or None
        Randomness of the noise; give an int for reproducible data.

    Returns
    -------
    Measurements
    """
    q2, _ = check_joint_values(q, true_robot.dof)
    sigma = broadcast_sigma(noise, q2.shape[0])
    positions = true_robot.position(q2)
    if np.any(sigma > 0):
        positions = positions + np.random.default_rng(seed).normal(size=positions.shape) * sigma
    return Measurements(q=q2, positions=positions, sigma=sigma)
