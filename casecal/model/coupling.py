"""Joint couplings: the model's joint values from the controller's, ``q_model = M q + b``.

A controller's joints need not be the kinematic model's. A heavy arm whose third axis is
driven through the second (a parallelogram) reports J3 while the model's third joint
turns by ``q3 = -(J2 + J3)``; a humanoid torso's passive joint follows two others,
``q_t4 = -(q_t2 + q_t3)``. `Coupling` holds that linear map (SI: a revolute model joint's
value in rad, a prismatic one's in m; `M` is then dimensionless). Every joint value a
user gives or gets (`casecal.Robot.fk`, `simulate`, `identify`, `read_csv`, `compensate`,
`casecal.poses`) is a controller joint value; the kinematic kernels keep the model's
joints, and the map is applied once where the values come in (`Robot.model_joints`), the
joint Jacobian multiplied by `M`.

Joint limits bound the controller joints (what a program commands, what
`casecal.poses.uniform` samples, what `compensate` keeps its answers in): with as many
controller joints as model joints, the model's joint rows carry them, row i for controller
joint i (a data sheet's joint ranges are the controller's); with fewer, the coupling
carries them (`Coupling.limits`) and the model's rows carry none.

In a robot file (`casecal.load_robot`), a ``[coupling]`` table; each key ``q{i}`` names a
model joint (``[[joints]]`` row i) and gives it as a combination of controller joints
(the CSV's ``q1`` … ``qn``), with an optional constant ``offset`` in the file's angle or
length unit; a model joint not listed is the controller joint of its number::

    [coupling]
    q3 = {q2 = -1.0, q3 = -1.0}          # the model's q3 = -(J2 + J3)

    [coupling]                           # a torso: 4 model joints, 3 controller joints
    controller_joints = 3
    q4 = {q2 = -1.0, q3 = -1.0, offset = 0.0}
    limits = [[-45.0, 45.0], [-30.0, 30.0], [-30.0, 30.0]]   # per controller joint
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError


@dataclass(frozen=True)
class ControllerJoint:
    """A controller joint: its type ("R" or "P") and limits (rad or m; None: none given)."""

    type: str
    limits: tuple[float, float] | None = None


@dataclass(frozen=True)
class Coupling:
    """``q_model = M q_controller + b``, SI (module doc).

    Attributes
    ----------
    matrix : tuple of tuple of float
        M, shape (n_model, n_controller), one row per model joint.
    offset : tuple of float
        b, shape (n_model,), rad (revolute model joint) or m (prismatic).
    limits : tuple of ((float, float) or None)
        Per controller joint, only when there are fewer controller joints than model
        joints (else the model's joint rows carry them); None: no limits given (a revolute
        joint then spans ±π where poses are sampled, as without a coupling).
    """

    matrix: tuple
    offset: tuple
    limits: tuple = ()

    @property
    def M(self) -> np.ndarray:
        """The matrix, shape (n_model, n_controller)."""
        return np.array(self.matrix, dtype=float).reshape(len(self.matrix), -1)

    @property
    def b(self) -> np.ndarray:
        """The offset, shape (n_model,)."""
        return np.array(self.offset, dtype=float)

    @property
    def n_model(self) -> int:
        return len(self.matrix)

    @property
    def n_controller(self) -> int:
        return len(self.matrix[0])

    @property
    def square(self) -> bool:
        return self.n_model == self.n_controller

    def model(self, q: np.ndarray) -> np.ndarray:
        """Model joint values of controller values `q`, (N, n_controller + inputs) to
        (N, n_model + inputs): per-pose inputs after the joints pass through."""
        n = self.n_controller
        out = q[:, :n] @ self.M.T + self.b
        return np.ascontiguousarray(np.concatenate([out, q[:, n:]], axis=1))

    def describe(self, types: str) -> list[str]:
        """One line per coupled model joint, e.g. ``"q3 = -q2 - q3"`` (offsets in mm/deg)."""
        M, b = self.M, self.b
        lines = []
        for i in range(self.n_model):
            if self.square and _identity_row(M[i], i) and b[i] == 0:
                continue
            terms = []
            for j, c in enumerate(M[i]):
                if c == 0:
                    continue
                sign = "-" if c < 0 else "+"
                size = "" if abs(c) == 1 else f"{abs(c):.6g}·"
                terms.append(f"{sign} {size}q{j + 1}")
            if b[i] != 0 or not terms:
                value = math.degrees(b[i]) if types[i] == "R" else b[i] * 1e3
                unit = "°" if types[i] == "R" else " mm"
                terms.append(f"{'-' if value < 0 else '+'} {abs(value):.6g}{unit}")
            text = " ".join(terms)
            text = text[2:] if text.startswith("+ ") else "-" + text[2:]
            lines.append(f"model q{i + 1} = {text}")
        return lines


def _identity_row(row: np.ndarray, i: int) -> bool:
    return row[i] == 1 and np.count_nonzero(row) == 1


def make_coupling(matrix, offset, limits, joints, label: str) -> Coupling | None:
    """A checked `Coupling` of `joints` (the model's rows), None for the identity.

    Raises
    ------
    CalibrationError
        A matrix of the wrong shape or with non-finite entries, a controller joint that
        drives nothing or drives revolute and prismatic joints alike, controller joints
        that move the model alike (rank below their number), more controller joints than
        model joints, limits given twice or of the wrong shape.
    """
    try:
        M = np.array(matrix, dtype=float)
    except (TypeError, ValueError):
        raise CalibrationError(
            f"{label}: the coupling matrix must be numbers, shape (model joints, controller joints)"
        ) from None
    n = len(joints)
    if M.ndim != 2 or M.shape[0] != n or M.shape[1] < 1:
        raise CalibrationError(
            f"{label}: the coupling matrix has shape {M.shape}; it needs one row per model "
            f"joint ({n}) and one column per controller joint"
        )
    if not np.all(np.isfinite(M)):
        raise CalibrationError(f"{label}: the coupling matrix has a non-finite entry")
    k = M.shape[1]
    if k > n:
        raise CalibrationError(
            f"{label}: {k} controller joints for {n} model joints; a coupling maps the "
            "controller's joints onto at least as many model joints"
        )
    try:
        b = np.zeros(n) if offset is None else np.array(offset, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise CalibrationError(f"{label}: the coupling offset must be {n} numbers") from None
    if b.shape != (n,) or not np.all(np.isfinite(b)):
        raise CalibrationError(
            f"{label}: the coupling offset must be {n} finite numbers (one per model joint), "
            "rad or m"
        )
    types = "".join(j.type for j in joints)
    for c in range(k):
        driven = {types[i] for i in np.flatnonzero(M[:, c])}
        if not driven:
            raise CalibrationError(
                f"{label}: controller joint {c + 1} drives no model joint (its column of the "
                "coupling is zero); leave it out"
            )
        if len(driven) > 1:
            raise CalibrationError(
                f"{label}: controller joint {c + 1} drives revolute and prismatic model "
                "joints alike; a coupling between joint types is not supported"
            )
    if np.linalg.matrix_rank(M) < k:
        raise CalibrationError(
            f"{label}: the coupling moves the model alike for different controller joint "
            "values (its matrix has rank below its number of columns); no calibration "
            "could tell those joints apart, and no compensation could set them"
        )
    if k == n and np.array_equal(M, np.eye(n)) and not np.any(b):
        if limits:
            raise CalibrationError(_TWICE.format(label=label))
        return None  # the identity is no coupling: the same robot
    limits = tuple(limits or ())
    if k == n:
        if limits:
            raise CalibrationError(_TWICE.format(label=label))
    else:
        if any(j.limits is not None for j in joints):
            raise CalibrationError(
                f"{label}: with {k} controller joints for {n} model joints, joint limits "
                "bound the controller joints and are given with the coupling (limits=, or "
                "limits in [coupling]); the model's joint rows must not carry any"
            )
        limits = _controller_limits(limits, k, M, types, label)
    return Coupling(
        tuple(tuple(float(v) for v in row) for row in M),
        tuple(float(v) for v in b),
        limits,
    )


_TWICE = (
    "{label}: with as many controller joints as model joints the model's joint rows carry "
    "the limits (row i for controller joint i); give none with the coupling"
)


def _controller_limits(limits, k: int, M: np.ndarray, types: str, label: str) -> tuple:
    if not limits:
        limits = (None,) * k
    if len(limits) != k:
        raise CalibrationError(
            f"{label}: the coupling's limits must give one [min, max] (or None) per "
            f"controller joint ({k})"
        )
    out = []
    for c, lim in enumerate(limits):
        kind = controller_type(M, types, c)
        if lim is None:
            if kind == "P":
                raise CalibrationError(
                    f"{label}: prismatic controller joint {c + 1} has no limits; give them "
                    "with the coupling"
                )
            out.append(None)
            continue
        try:
            lo, hi = (float(v) for v in lim)
        except (TypeError, ValueError):
            raise CalibrationError(
                f"{label}: limits of controller joint {c + 1} must be [min, max]"
            ) from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise CalibrationError(
                f"{label}: limits of controller joint {c + 1} must be finite with min below max"
            )
        out.append((lo, hi))
    return tuple(out)


def controller_limits_of_rows(matrix, offset, joints, label: str) -> list:
    """Per controller joint, the limits of the model joint it alone drives, SI.

    A model joint ``q_i = c q_k + b_i`` (row i of `matrix` nonzero in column k only) with
    limits [lo, hi] bounds controller joint k to ``[(lo - b_i) / c, (hi - b_i) / c]``
    (sorted); several such rows, the tightest of them. Used where the model's joint rows
    carry limits (a URDF's) and the controller has fewer joints (`Robot.with_coupling`).

    Raises
    ------
    CalibrationError
        A controller joint that drives no limited model joint alone (give ``limits=``),
        or whose rows' ranges do not overlap.
    """
    try:
        M = np.array(matrix, dtype=float)
        b = np.zeros(len(M)) if offset is None else np.array(offset, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return None  # `make_coupling` says what is wrong with them
    if M.ndim != 2 or b.shape != (M.shape[0],) or not np.all(np.isfinite(M)):
        return None
    out = []
    for k in range(M.shape[1]):
        ranges = []
        for i in np.flatnonzero(M[:, k]):
            if np.count_nonzero(M[i]) == 1 and joints[i].limits is not None:
                lo, hi = ((v - b[i]) / M[i, k] for v in joints[i].limits)
                ranges.append((min(lo, hi), max(lo, hi)))
        if not ranges:
            raise CalibrationError(
                f"{label}: controller joint {k + 1} drives no model joint alone whose limits "
                "could bound it; give its limits with the coupling (limits=[[min, max], …], "
                "one per controller joint, rad or m)"
            )
        lo, hi = max(r[0] for r in ranges), min(r[1] for r in ranges)
        if not lo < hi:
            raise CalibrationError(
                f"{label}: the model joints controller joint {k + 1} drives alone have "
                "limits that do not overlap; give its limits with the coupling (limits=)"
            )
        out.append((float(lo), float(hi)))
    return out


def controller_type(M: np.ndarray, types: str, c: int) -> str:
    """The type of controller joint `c` (0-based): that of the model joints it drives."""
    return types[int(np.flatnonzero(M[:, c])[0])]


def hull(coupling: Coupling, limits: np.ndarray) -> list[tuple[float, float]]:
    """Per model joint, the range the controller joints' box `limits` (n_controller, 2)
    maps it into: ``b + Σ min/max(M_ij lo_j, M_ij hi_j)``, SI."""
    M, b = coupling.M, coupling.b
    lo = b + np.sum(np.minimum(M * limits[:, 0], M * limits[:, 1]), axis=1)
    hi = b + np.sum(np.maximum(M * limits[:, 0], M * limits[:, 1]), axis=1)
    return [(float(a), float(c)) for a, c in zip(lo, hi, strict=True)]
