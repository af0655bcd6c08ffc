"""Every robot file casecal writes is read back and compared before it replaces anything.

A format's `Contract` says what its file holds of a robot: the robot the file is compared
with (`reference`: the saved robot, its base frame removed where the format has no place
for the instrument's frame), the robot the file reads back as when the writer is right
(`held`: the reference less what the format cannot hold), and how to read the text back
with casecal's own reader (the same chain ends, the same tool frame). `verified` reads the
text back in memory and compares forward kinematics at `N_POSES` poses across the joint
ranges (seed 0): the tool frame's origin and orientation and every measured point (a
tree's: every tip's frame).

- read-back ≠ held (beyond `EXACT`): a bug in a writer; `CalibrationError`, nothing written;
- reference ≠ read-back: a real loss, stated in mm and degrees with its reasons;
- otherwise the file holds everything the robot is (to 1e-9 m and 1e-9 rad).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError, CalibrationWarning
from ._evaluate import COMPILE_MIN_POSES

N_POSES = 300
"""Poses of the read-back check, uniform inside the joint limits (seed 0)."""

EXACT = 1e-9
"""A file that reads back this close (m at the tool and the points, rad) holds the robot."""

_FREE_STROKE = (-1.0, 1.0)
"""Range (m) of the check for a prismatic joint without limits (TOML only: a URDF needs
them)."""


@dataclass(frozen=True)
class Difference:
    """The largest difference between two robots over the check's poses.

    Attributes
    ----------
    position : float
        m, at the tool frame's origin and every measured point.
    angle : float
        rad, of the tool frame's orientation.
    """

    position: float
    angle: float

    @property
    def exact(self) -> bool:
        """Both within `EXACT`."""
        return self.position <= EXACT and self.angle <= EXACT

    def __str__(self) -> str:
        # what is within EXACT is rounding: "0.000", not "4.2e-14"
        position = self.position if self.position > EXACT else 0.0
        angle = self.angle if self.angle > EXACT else 0.0
        return f"{_mm(position)} mm and {_deg(angle)}°"


class ExportLossWarning(CalibrationWarning):
    """`casecal.save_robot` wrote a file that does not hold the whole robot.

    Attributes
    ----------
    path : str
    loss : Difference
        The largest difference of the file's robot from the saved one (m, rad).
    """

    def __init__(self, message: str, path: str, loss: Difference):
        super().__init__(message)
        self.path, self.loss = path, loss


@dataclass(frozen=True)
class Contract:
    """What a file of one format holds of one robot (module doc).

    Attributes
    ----------
    what : str
        The format in words, e.g. "a UR kinematics file".
    reference, held : Robot
    read : callable
        The file's text to the robot casecal reads from it (with the saved robot's
        measured points where the format has none, and the same tool frame semantics).
    tool_reason : str
        Why the format cannot hold the tool side (the part of `reference` without error
        terms that `held` lacks), and how to keep it; "" when it holds all of it.
    terms_reason : str
        The same for the error terms beyond geometry; "" when the format holds them.
    """

    what: str
    reference: object
    held: object
    read: Callable[[str], object]
    tool_reason: str = ""
    terms_reason: str = ""


@dataclass(frozen=True)
class Export:
    """A robot file's text, checked.

    Attributes
    ----------
    text : str
    notes : tuple of str
        What the format could not hold and where it went, one sentence each; the loss
        statement (if any) first.
    loss : Difference
        The file's robot against the saved one (m, rad); `Difference.exact` when the file
        holds everything.
    statement : str
        The loss in mm and degrees and why, or "" when there is none.
    """

    text: str
    notes: tuple[str, ...]
    loss: Difference
    statement: str


def check_poses(robot, n: int = N_POSES, seed: int = 0) -> np.ndarray:
    """The check's joint values, uniform inside `robot`'s limits, shape (n, dof).

    Revolute joints without limits span ±π, prismatic ones ±1 m.
    """
    rows = []
    for j in robot.controller_joints:  # the joints the robot takes (a coupling's controller's)
        if j.limits is not None:
            rows.append(j.limits)
        else:
            rows.append((-np.pi, np.pi) if j.type == "R" else _FREE_STROKE)
    limits = np.array(rows, dtype=float)
    return np.random.default_rng(seed).uniform(limits[:, 0], limits[:, 1], (n, robot.dof))


def difference(a, b, q: np.ndarray) -> Difference:
    """The largest difference of robot `b` from robot `a` at poses `q` (N, dof).

    Position: the tool frame's origin and, for robots with measured points, each point
    (the two must have as many); orientation: the angle of ``R_a(q)ᵀ R_b(q)``. A tree's:
    every tip's frame (the two must have the same tips).
    """
    if len(a.points) != len(b.points) or a.is_tree != b.is_tree:
        return Difference(np.inf, np.inf)
    if a.is_tree and a.tips != b.tips:  # a serial robot's one tip may be named otherwise
        return Difference(np.inf, np.inf)
    position, angle = 0.0, 0.0
    # batches below the compile threshold: a one-off check should not compile a C kernel
    # for every structure it meets
    for rows in np.array_split(q, -(-len(q) // (COMPILE_MIN_POSES - 1))):
        # a tree's tips' frames (N, tips, 4, 4) as N · tips frames: each compared
        Ta, Tb = a.fk(rows).reshape(-1, 4, 4), b.fk(rows).reshape(-1, 4, 4)
        gap = [np.linalg.norm(Ta[:, :3, 3] - Tb[:, :3, 3], axis=-1)]
        if a.points:
            gap.append(
                np.linalg.norm(a.measured_points(rows) - b.measured_points(rows), axis=-1).ravel()
            )
        # the angle between two rotations from their Frobenius distance, 2√2 sin(θ/2):
        # no arccos of a trace, which loses half the digits near 0
        chord = np.linalg.norm(Ta[:, :3, :3] - Tb[:, :3, :3], axis=(1, 2)) / (2 * np.sqrt(2))
        position = max(position, float(np.max(np.concatenate(gap))))
        angle = max(angle, float(np.max(2 * np.arcsin(np.minimum(chord, 1.0)))))
    return Difference(position, angle)


def verified(path, text: str, notes, contract: Contract) -> Export:
    """Read `text` back as `contract` says and compare (module doc).

    Raises
    ------
    CalibrationError
        The text does not read back, or reads back other than the contract's `held`
        robot: a writer's bug; the message names the file and the difference in mm.
    """
    label = str(path)
    try:
        back = contract.read(text)
    except CalibrationError as exc:
        raise CalibrationError(
            f"{label}: not written: casecal's text for {contract.what} does not read back "
            f"({exc}); this is a bug in casecal, please report it; save as .toml meanwhile"
        ) from None
    reference = contract.reference
    q = check_poses(reference)
    wrong = difference(contract.held, back, q)
    if not wrong.exact:
        raise CalibrationError(
            f"{label}: not written: {contract.what} of robot {reference.name!r} reads back "
            f"up to {wrong} away from what it should hold; this is a bug in casecal, please "
            "report it; save as .toml meanwhile"
        )
    loss = difference(reference, back, q)
    notes = list(notes)
    statement = ""
    if not loss.exact:
        # which part is lost: the error terms (reference against its geometry) and the
        # tool side (the geometry against what the format holds)
        geometry = reference
        parts = []
        if contract.terms_reason:
            geometry = dataclasses.replace(reference, terms=(), auto_beta=False)
            parts.append((difference(reference, geometry, q), contract.terms_reason))
        if contract.tool_reason:
            parts.insert(0, (difference(geometry, contract.held, q), contract.tool_reason))
        reasons = [reason for part, reason in parts if not _negligible(part)]
        where = "at the tool and the measured points" if reference.points else "at the tool"
        where = "at the tips" if reference.is_tree else where
        statement = f"this file loses up to {loss} {where}: " + "; ".join(
            reasons or ["what it cannot hold"]
        )
        notes.insert(0, statement)
    elif contract.terms_reason:
        notes.append(contract.terms_reason)  # terms without effect (all zero): still unsaid
    return Export(text, tuple(notes), loss, statement)


def _negligible(d: Difference) -> bool:
    return d.position <= EXACT / 2 and d.angle <= EXACT / 2


def _mm(metres: float) -> str:
    v = metres * 1e3
    return f"{v:.3f}" if v == 0 or v >= 0.01 or not np.isfinite(v) else f"{v:.2g}"


def _deg(radians: float) -> str:
    v = np.degrees(radians)
    return f"{v:.3f}" if v == 0 or v >= 0.01 or not np.isfinite(v) else f"{v:.2g}"


def tcp_text(T: np.ndarray) -> str:
    """A tool frame (4 × 4, m) as a UR controller's TCP: mm and a rotation vector in
    degrees, and the same in URScript's ``set_tcp`` (m, rad)."""
    from .frames import rotation_vector

    xyz, w = T[:3, 3], rotation_vector(T[:3, :3])
    # + 0.0 and the rounding: no "-0.0000" and no 1e-18 of rounding noise in the numbers
    mm = ", ".join(f"{a}={round(v * 1e3, 4) + 0.0:.4f}" for a, v in zip("xyz", xyz, strict=True))
    deg = ", ".join(
        f"r{a}={round(np.degrees(v), 5) + 0.0:.5f}°" for a, v in zip("xyz", w, strict=True)
    )
    script = ", ".join(f"{round(float(v), 12) + 0.0:.12g}" for v in (*xyz, *w))
    return f"{mm} mm, rotation vector {deg} (URScript: set_tcp(p[{script}]))"
