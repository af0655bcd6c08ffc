"""Measurements of a robot's tool point, and their simulation from a 'true' robot."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError
from ..model.frames import rotation_from_vector, rotation_vector  # noqa: F401 (re-export)
from ..model.parameters import check_session_label
from ..model.robot import Frame, Robot, check_joint_values


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
    stated = out[out > 0]
    lo, hi = SIGMA_RANGE  # defined below: read at call time
    if stated.size and (stated.min() < lo or stated.max() > hi):
        bad = stated.min() if stated.min() < lo else stated.max()
        raise CalibrationError(
            f"noise sigma {bad:.3g} m is outside 1 nm … 1 m, the range of position "
            "instruments: check its unit (the API takes m, files and the command line mm); "
            "give 0 for noise-free or unknown noise"
        )
    return out


SIGMA_RANGE = (1e-9, 1.0)
"""Stated noise σ (m) outside this range is a unit mistake, not an instrument: 1 nm … 1 m."""


@dataclass(frozen=True)
class Measurements:
    """Joint readings and what was measured at those poses.

    Attributes
    ----------
    q : ndarray, shape (N, dof)
        Joint values, rad (R) or m (P).
    positions : ndarray, shape (N, 3) or (N, m, 3)
        Measured positions in the world (instrument) frame, m: one point per pose, or m
        points (reflectors) per pose in the order of the robot's ``points`` (a tree's: one
        per tip, in the order of its ``tips``).
    sigma : ndarray, shape (N, 3)
        Standard deviation of the position noise per pose and axis, m (every point of a
        pose shares it); a scalar, (3,) or (N,) value is broadcast. Zero means noise-free
        (simulated) data or unknown noise.
    orientations : ndarray, shape (N, 3, 3), optional
        Measured rotation of the tool frame in the world frame (from unit quaternions).
    orientation_sigma : float, optional
        Standard deviation of the orientation noise, rad.
    session : ndarray of str, shape (N,), optional
        The measurement session of each pose, for data taken with the instrument (or the
        probe) re-mounted between sessions: any labels of letters, digits, ``_`` and ``-``
        (they name the sessions' frames, ``base_x@LABEL``). `casecal.identify` fits one
        robot to all of them, with a base frame per session. None: one session.
    """

    q: np.ndarray
    positions: np.ndarray
    sigma: np.ndarray
    orientations: np.ndarray | None = None
    orientation_sigma: float | None = None
    session: np.ndarray | None = None

    def __post_init__(self) -> None:
        q, _ = check_joint_values(self.q, np.shape(self.q)[-1] if np.ndim(self.q) else 0)
        try:
            y = np.asarray(self.positions, dtype=float)
        except (TypeError, ValueError):
            raise CalibrationError("measured positions are not numbers") from None
        if y.ndim == 1:
            y = y[None, :]
        if y.shape[0] != q.shape[0] or y.shape[-1] != 3 or y.ndim not in (2, 3) or y.size == 0:
            raise CalibrationError(
                f"measured positions have shape {y.shape}; expected ({q.shape[0]}, 3) for one "
                f"point per pose or ({q.shape[0]}, m, 3) for m points"
            )
        if not np.all(np.isfinite(y)):
            raise CalibrationError("measured positions contain NaN or inf; remove those rows")
        sigma = broadcast_sigma(self.sigma, q.shape[0])
        values = [("q", q), ("positions", y), ("sigma", sigma)]
        if self.orientations is not None:
            try:
                R = np.asarray(self.orientations, dtype=float)
            except (TypeError, ValueError):
                raise CalibrationError("orientations are not numbers") from None
            if R.shape != (q.shape[0], 3, 3) or not np.all(np.isfinite(R)):
                raise CalibrationError(f"orientations must be ({q.shape[0]}, 3, 3) rotations")
            if np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max() > 1e-6 or np.any(
                np.linalg.det(R) < 0
            ):
                raise CalibrationError("orientations are not rotations (R Rᵀ != I or det R < 0)")
            values.append(("orientations", R))
        if self.orientation_sigma is not None:
            try:
                sd = float(self.orientation_sigma)
            except (TypeError, ValueError):
                raise CalibrationError("orientation sigma is not a number (rad)") from None
            if not (np.isfinite(sd) and sd >= 0):
                raise CalibrationError("orientation sigma must be finite and non-negative (rad)")
            object.__setattr__(self, "orientation_sigma", sd)
        if self.session is not None:
            values.append(("session", _session_labels(self.session, q.shape[0])))
        for name, value in values:
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n_poses(self) -> int:
        """Number of poses N."""
        return self.q.shape[0]

    @property
    def points(self) -> np.ndarray:
        """Measured positions as (N, m, 3), m."""
        return self.positions.reshape(self.n_poses, -1, 3)

    @property
    def n_points(self) -> int:
        """Measured points per pose, m."""
        return self.points.shape[1]

    @property
    def sessions(self) -> tuple[str, ...]:
        """The session labels in order of first appearance; () without a `session`."""
        if self.session is None:
            return ()
        return tuple(dict.fromkeys(self.session.tolist()))

    def take(self, index) -> Measurements:
        """The measurements of the poses `index` (indices or a boolean mask)."""
        return Measurements(
            self.q[index],
            self.positions[index],
            self.sigma[index],
            None if self.orientations is None else self.orientations[index],
            self.orientation_sigma,
            None if self.session is None else self.session[index],
        )

    def concat(self, other: Measurements) -> Measurements:
        """These measurements followed by `other`'s (same robot and kind)."""
        if (self.orientations is None) != (other.orientations is None) or (
            self.positions.shape[1:] != other.positions.shape[1:]
        ):
            raise CalibrationError("cannot join measurements of different kinds")
        if (self.session is None) != (other.session is None):
            raise CalibrationError(
                "cannot join measurements with sessions to measurements without; give both "
                "a session label per pose, or neither"
            )
        orient = (
            None
            if self.orientations is None
            else np.concatenate([self.orientations, other.orientations])
        )
        return Measurements(
            np.vstack([self.q, other.q]),
            np.concatenate([self.positions, other.positions]),
            np.vstack([self.sigma, other.sigma]),
            orient,
            self.orientation_sigma,
            None if self.session is None else np.concatenate([self.session, other.session]),
        )


def _session_labels(session, n: int) -> np.ndarray:
    """`session` as an (n,) array of clean labels (`check_session_label`), or an error."""
    if isinstance(session, str):
        raise CalibrationError(
            f"session must give one label per pose ({n}), not one string; e.g. "
            "np.full(n, 'A') for a single session"
        )
    try:
        labels = list(session)
    except TypeError:
        raise CalibrationError(f"session must be {n} labels (str), one per pose") from None
    if len(labels) != n:
        raise CalibrationError(f"session has {len(labels)} labels for {n} poses; give one per pose")
    try:
        distinct = dict.fromkeys(labels)
    except TypeError:
        raise CalibrationError("session labels must be text (str), one per pose") from None
    for label in distinct:
        check_session_label(label, f"first at pose {labels.index(label)}")
    return np.array(labels, dtype=str)


def simulate(
    true_robot: Robot,
    q,
    noise=0.0,
    seed=None,
    orientation_noise=None,
    *,
    session=None,
    frames=None,
    tools=None,
) -> Measurements:
    """Measurements of `true_robot` at poses `q`, with isotropic Gaussian noise.

    Measures the robot's ``points`` (or the tool origin when it has none; a tree's tips,
    positions (N, tips, 3)); with `orientation_noise` (rad, may be 0) also the tool frame's
    rotation, perturbed by a random rotation vector of that standard deviation per axis.

    Sessions: with `session` (one label per pose) the measurements carry those labels,
    and each session may see the robot from an instrument of its own: `frames` maps a
    label to that session's base frame (the instrument-to-robot transform: a `Frame`, or
    ``(xyz, rpy)`` in m and rad), `tools` likewise to its tool frame (a re-mounted probe).
    A session not in them sees the robot's own `base` and `tool`.

    Examples
    --------
    >>> labels = np.repeat(["A", "B"], 50)                                  # doctest: +SKIP
    >>> meas = simulate(true, q, 5e-5, seed=1, session=labels,              # doctest: +SKIP
    ...                 frames={"B": ((2.0, 0.5, 0.0), (0.0, 0.0, np.pi / 3))})

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
    from ..design.poses import rng_from

    q2, _ = check_joint_values(q, true_robot.dof, len(true_robot.inputs))
    if true_robot.is_tree and orientation_noise is not None:
        from ..model.kinematics import tree_refusal

        raise tree_refusal("orientation measurements")
    sigma = broadcast_sigma(noise, q2.shape[0])
    rng = rng_from(seed)
    parts = _session_robots(true_robot, q2.shape[0], session, frames, tools)
    if orientation_noise is not None:
        if not isinstance(orientation_noise, int | float) or not orientation_noise >= 0:
            raise CalibrationError("orientation_noise must be a non-negative number (rad)")
    n_points = len(true_robot.tips) if true_robot.is_tree else max(len(true_robot.points), 1)
    points = np.empty((q2.shape[0], n_points, 3))
    R = None if orientation_noise is None else np.empty((q2.shape[0], 3, 3))
    for robot, rows in parts:  # each session through its own robot (one, without sessions)
        points[rows] = robot.measured_points(q2[rows])  # (N, m, 3)
        if R is not None:
            R[rows] = robot.fk(q2[rows])[:, :3, :3]
    if np.any(sigma > 0):
        points = points + rng.normal(size=points.shape) * sigma[:, None, :]
    positions = points if true_robot.points or true_robot.is_tree else points[:, 0, :]
    if R is not None and orientation_noise > 0:
        R = rotation_from_vector(rng.normal(scale=orientation_noise, size=(len(q2), 3))) @ R
    return Measurements(
        q=q2,
        positions=positions,
        sigma=sigma,
        orientations=R,
        orientation_sigma=orientation_noise,
        session=session,
    )


def _session_robots(true_robot: Robot, n: int, session, frames, tools) -> list:
    """[(robot, rows)]: the robot each session sees (its base and tool from `frames` and
    `tools`), and that session's rows (a slice of all rows without sessions)."""
    if session is None:
        if frames or tools:
            raise CalibrationError("frames= and tools= need session= (one label per pose)")
        return [(true_robot, slice(None))]
    if tools and true_robot.is_tree:
        raise CalibrationError("a tree has no tool frame to re-mount: give frames= only")
    labels = _session_labels(session, n)
    known = dict.fromkeys(labels.tolist())
    out = []
    chosen = {}
    for what, given in (("base", frames or {}), ("tool", tools or {})):
        unknown = [k for k in given if k not in known]
        if unknown:
            raise CalibrationError(
                f"{'frames' if what == 'base' else 'tools'} names session {unknown[0]!r}, "
                f"which no pose has; the sessions are {', '.join(known)}"
            )
        chosen[what] = {k: _frame(v, f"{what} of session {k!r}") for k, v in given.items()}
    for label in known:
        robot = dataclasses.replace(
            true_robot,
            base=chosen["base"].get(label, true_robot.base),
            tool=chosen["tool"].get(label, true_robot.tool),
            auto_beta=False,
        )
        out.append((robot, np.flatnonzero(labels == label)))
    return out


def _frame(value, what: str) -> Frame:
    """A `Frame`, or ``(xyz, rpy)`` (m, rad) as one."""
    if isinstance(value, Frame):
        frame = value
    else:
        try:
            xyz, rpy = value
            frame = Frame(tuple(float(v) for v in xyz), tuple(float(v) for v in rpy))
        except (TypeError, ValueError):
            raise CalibrationError(
                f"{what}: give a casecal.Frame or (xyz, rpy) in m and rad, not {value!r}"
            ) from None
    values = [*frame.xyz, *frame.rpy]
    if len(frame.xyz) != 3 or len(frame.rpy) != 3 or not np.all(np.isfinite(values)):
        raise CalibrationError(f"{what}: xyz and rpy need 3 finite numbers each (m, rad)")
    return frame
