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
    isotropic; with n = 3 three values are read per axis) or an (n, 3) array. ``inf``
    means the coordinate was not measured (a touch probe on a plane measures only the
    coordinate along its normal): its weight in a fit is 0.
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
    if np.any(np.isnan(out)) or np.any(out < 0):
        raise CalibrationError(
            "noise sigma must be non-negative (m), or inf for a coordinate not measured"
        )
    stated = out[(out > 0) & np.isfinite(out)]
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
    contact : dict of str to str, optional
        Sessions measured without a tracker, by contact (`casecal.identification.contact`):
        label -> ``"point"`` (the tool tip held in one fixed point, a sphere or cone, in
        many orientations: its position there is (0, 0, 0) in the session's own frame) or
        ``"plane"`` (a touch probe touching one plane: only the coordinate along the
        plane's normal is measured, 0, and σ of x and y is inf). Their rows carry no
        measured position: give 0 or NaN there; they are stored as 0, with σ inf where
        not measured. Other sessions are ordinary measured points.

    A coordinate whose σ is inf was not measured: its position may be NaN (stored as 0)
    and it weighs nothing in a fit.
    """

    q: np.ndarray
    positions: np.ndarray
    sigma: np.ndarray
    orientations: np.ndarray | None = None
    orientation_sigma: float | None = None
    session: np.ndarray | None = None
    contact: dict | None = None

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
        sigma = broadcast_sigma(self.sigma, q.shape[0])
        session = None if self.session is None else _session_labels(self.session, q.shape[0])
        contact = _contact(self.contact, session)
        if contact:
            y, sigma = _contact_rows(y, sigma, session, contact, self.orientations)
        # a coordinate not measured (σ inf) has no position: stored as 0, so that no NaN
        # reaches a fit (its weight there is 0)
        unmeasured = np.broadcast_to(np.isinf(sigma)[:, None, :], y.reshape(len(q), -1, 3).shape)
        if np.any(unmeasured):
            y = np.where(unmeasured.reshape(y.shape), 0.0, y)
            if np.all(unmeasured):
                raise CalibrationError(
                    "every coordinate's sigma is inf (not measured): there is nothing to fit; "
                    "give the measured coordinates their sigma (m)"
                )
        if not np.all(np.isfinite(y)):
            raise CalibrationError("measured positions contain NaN or inf; remove those rows")
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
        if session is not None:
            values.append(("session", session))
        for name, value in values:
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "contact", contact or None)

    @property
    def measured(self) -> np.ndarray:
        """(N, 3) bool: the coordinates measured (σ not inf), shared by a pose's points."""
        return ~np.isinf(self.sigma)

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
            self._contact_of(None if self.session is None else self.session[index]),
        )

    def _contact_of(self, session) -> dict | None:
        """`contact` of the sessions left in `session` (None if none)."""
        if not self.contact or session is None:
            return None
        left = set(session.tolist())
        return {k: v for k, v in self.contact.items() if k in left} or None

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
            _joined_contact(self.contact, other.contact),
        )


CONTACT_KINDS = ("point", "plane")
"""What a contact session measures: a fixed point, or a plane (`Measurements.contact`)."""


def _joined_contact(a: dict | None, b: dict | None) -> dict | None:
    a, b = a or {}, b or {}
    clash = [k for k in a if k in b and a[k] != b[k]]
    if clash:
        raise CalibrationError(
            f"session {clash[0]!r} is a {a[clash[0]]} in one part and a {b[clash[0]]} in the "
            "other; give each session one kind"
        )
    return {**a, **b} or None


def _contact(contact, session) -> dict:
    """`contact` checked: label -> kind, for labels `session` has."""
    if contact is None or (hasattr(contact, "__len__") and len(contact) == 0):
        return {}
    if not hasattr(contact, "items"):
        raise CalibrationError(
            f"contact must map session labels to 'point' or 'plane', e.g. "
            f"{{'P1': 'plane'}}, not {contact!r}"
        )
    if session is None:
        raise CalibrationError(
            "contact names sessions, but the measurements have no session labels; give "
            "session= (one label per pose) too"
        )
    known = dict.fromkeys(session.tolist())
    out = {}
    for label, kind in contact.items():
        if label not in known:
            raise CalibrationError(
                f"contact names session {label!r}, which no pose has; the sessions are "
                f"{', '.join(map(str, known))}"
            )
        if kind not in CONTACT_KINDS:
            raise CalibrationError(
                f"contact session {label!r} is {kind!r}; give 'point' (the tool tip held in "
                "one fixed point) or 'plane' (a probe touching a plane)"
            )
        out[str(label)] = str(kind)
    return out


def _contact_rows(y, sigma, session, contact, orientations):
    """Positions and σ with the contact sessions' rows as they are: 0 where measured,
    and σ inf for a plane's x and y (not measured)."""
    if y.ndim == 3 and y.shape[1] != 1:
        raise CalibrationError(
            f"contact sessions measure one point (the tool tip) per pose, but the positions "
            f"have {y.shape[1]} per pose; give contact data of one point"
        )
    if orientations is not None:
        raise CalibrationError(
            "contact sessions measure no orientation; give orientations=None with contact"
        )
    y = np.array(y, dtype=float)
    sigma = sigma.copy()
    flat = y.reshape(len(y), 3)
    for label, kind in contact.items():
        rows = session == label
        given = flat[rows]
        if np.any(np.isfinite(given) & (given != 0)):
            raise CalibrationError(
                f"contact session {label!r} ({kind}) has measured positions that are not 0; "
                "a contact row has no measured position (the fixed point or the plane is its "
                "frame's origin): leave x, y, z empty (NaN) or 0"
            )
        flat[rows] = 0.0
        if kind == "plane":
            sigma[rows, :2] = np.inf  # only the coordinate along the normal is measured
        elif np.any(np.isinf(sigma[rows])):
            raise CalibrationError(
                f"fixed-point session {label!r} has a coordinate with sigma inf: a fixed "
                "point is measured in x, y and z; give its sigma (m)"
            )
    return flat.reshape(y.shape), sigma


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


CONTACT_TOLERANCE = 1e-12
"""How close (m) `simulate_contact` puts a simulated tip onto its contact."""


def simulate_contact(
    true_robot: Robot,
    q,
    contact: dict,
    session,
    frames=None,
    noise=0.0,
    seed=None,
) -> Measurements:
    """Measurements of contact sessions (a fixed point, a plane) of `true_robot`.

    Each pose of a contact session is moved, by the least change of its joint values
    (Gauss-Newton on the true robot's tip), until the tip touches its session's point or
    plane; the returned `Measurements.q` are those moved poses, and their positions 0 (a
    contact measures no position). The noise is where the tip touched: a fixed point's
    tip lands at a Gaussian offset of σ per axis from the point, a plane's at σ along
    its normal. Poses of sessions not in `contact` are measured points (`simulate`).

    Parameters
    ----------
    true_robot : Robot
        A serial robot without inputs or couplings.
    q : array-like, shape (N, dof)
        Poses near the contacts, rad (R) or m (P): e.g. the wrist turned about a tip
        held near the point, or poses spread over the plane.
    contact : dict of str to {"point", "plane"}
        Which sessions are contacts (`Measurements.contact`).
    session : array-like of str, shape (N,)
        Each pose's session.
    frames : dict of str to Frame or (xyz, rpy), optional
        Each session's frame: the robot's base in it, m and rad. A fixed point is that
        frame's origin, a plane its z = 0 plane (normal: its z axis). Default: the
        robot's base.
    noise : float
        σ, m.
    seed : int, numpy Generator or None

    Returns
    -------
    Measurements
        With `contact`; σ of a plane's x and y inf (not measured).

    Raises
    ------
    CalibrationError
        A pose whose tip cannot be brought onto its contact from where it is.

    Examples
    --------
    >>> labels = np.repeat(["P1", "S"], 60)                                 # doctest: +SKIP
    >>> meas = simulate_contact(true, q, {"P1": "plane", "S": "point"}, labels,
    ...                         frames={"P1": plane_frame, "S": point_frame}, noise=2e-5)
    """
    from ..design.poses import rng_from

    if true_robot.is_tree or true_robot.inputs or true_robot.coupling is not None:
        raise CalibrationError(
            "simulate_contact takes a serial robot without inputs or joint couplings"
        )
    q2, _ = check_joint_values(q, true_robot.dof)
    n = q2.shape[0]
    labels = _session_labels(session, n)
    kinds = _contact(contact, labels)
    try:
        sigma_value = float(noise)
    except (TypeError, ValueError):
        raise CalibrationError(f"noise {noise!r}: give one σ in m") from None
    sigma = broadcast_sigma(sigma_value, n)
    if not np.all(np.isfinite(sigma)):
        raise CalibrationError("noise sigma of a simulation must be finite (m)")
    rng = rng_from(seed)
    offsets = rng.normal(size=(n, 3)) * sigma  # where each tip touches, or its noise
    q2 = q2.copy()
    positions = np.zeros((n, 3))
    for robot, rows in _session_robots(true_robot, n, labels, frames, None):
        label = str(labels[rows[0]])
        kind = kinds.get(label)
        if kind is None:  # a measured session: points with noise
            positions[rows] = robot.measured_points(q2[rows])[:, 0, :] + offsets[rows]
            continue
        axes = slice(None) if kind == "point" else slice(2, 3)
        q2[rows] = _onto(robot, q2[rows], offsets[rows], axes, label, rows)
    meas_sigma = sigma.copy()
    return Measurements(q2, positions, meas_sigma, session=labels, contact=kinds)


def _onto(robot: Robot, q: np.ndarray, target: np.ndarray, axes: slice, label, rows):
    """`q` moved by least change until the tip's coordinates `axes` in `robot`'s frame
    equal `target`'s (Gauss-Newton, central-difference Jacobian)."""
    h = 1e-6
    for _ in range(60):
        f = robot.measured_points(q)[:, 0, :]
        r = (target - f)[:, axes]  # (n, c)
        if np.max(np.abs(r)) < CONTACT_TOLERANCE:
            return q
        J = np.empty((len(q), r.shape[1], q.shape[1]))
        for j in range(q.shape[1]):
            step = np.zeros(q.shape[1])
            step[j] = h
            up = robot.measured_points(q + step)[:, 0, :]
            down = robot.measured_points(q - step)[:, 0, :]
            J[:, :, j] = ((up - down) / (2 * h))[:, axes]
        # least change: dq = Jᵀ (J Jᵀ)⁻¹ r per pose
        JJt = J @ np.swapaxes(J, 1, 2)
        dq = np.einsum("nij,ni->nj", J, np.linalg.solve(JJt, r[:, :, None])[:, :, 0])
        q = q + dq
    bad = int(rows[int(np.argmax(np.max(np.abs(r), axis=1)))])
    raise CalibrationError(
        f"pose {bad} of contact session {label!r} cannot be brought onto its contact (the "
        f"tip stays {np.max(np.abs(r)) * 1e3:.3g} mm off): give poses whose tips lie near it"
    )
