"""What a set of poses lets us see: rank, blind parameter combinations, observability indices.

Everything here works on the *scaled* identification Jacobian: each column of the stacked
3N × k Jacobian divided by its norm, so that metres and radians do not decide the rank. A
direction whose scaled singular value is below `RANK_TOLERANCE` times the largest is blind:
moving the parameters along it changes no measured position (to first order).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._threads import with_one_blas_thread
from ..errors import CalibrationError
from ..model.parameters import UNITS, facts_of, select, unit
from ..model.robot import Robot, check_joint_values

NULL_SHARE = 1e-6
"""Share of a unit null vector (scaled columns) below which a parameter is not counted in
that blind direction: ten times the rank tolerance's shares, far above rounding."""

RANK_TOLERANCE = 1e-8
"""Relative singular-value threshold of the scaled Jacobian below which a direction is blind.

Structurally blind directions sit at ~1e-16 (rounding); a direction at 1e-8 would amplify
measurement noise 1e8-fold, which no calibration can use. Between lies a wide gap.
"""

DEFAULT_PARAMETERS = ("theta*", "a*", "d*")
"""The paper's error set: θ, a, d per joint, α fixed."""


@dataclass(frozen=True)
class BlindSpot:
    """A group of parameters whose individual values the measurements cannot separate.

    Attributes
    ----------
    members : tuple of str
        The parameters of the group.
    blind : tuple of str
        Combinations that move no measured point (a basis of the null space in the group),
        written with coefficients in physical units, e.g. ``"d2 - d4"``.
    visible : str or None
        When the group's columns are all parallel: the one combination the data do see,
        e.g. ``"d2 + d3 + d4"``; None when the group has none (a zero column) or several.
    text : str
        One sentence in words.
    coefficients : tuple of float or None
        Of `visible`, per member, relative to the first member (physical units).
    """

    members: tuple[str, ...]
    blind: tuple[str, ...]
    visible: str | None
    text: str
    coefficients: tuple[float, ...] | None = None

    def visible_as(self, member: str) -> str | None:
        """`visible` written with `member` leading (coefficient 1): what its estimate means."""
        if self.coefficients is None:
            return None
        i = self.members.index(member)
        order = [i, *(k for k in range(len(self.members)) if k != i)]
        coeffs = np.array(self.coefficients)[order]
        return _expression(coeffs, [self.members[k] for k in order])


@dataclass(frozen=True)
class Observability:
    """Identifiability of a parameter set from a set of poses (see `observability`).

    Attributes
    ----------
    parameters : tuple of str
        The parameters asked about, canonical order.
    singular_values : ndarray, shape (k,)
        Of the column-scaled Jacobian, descending (zero columns contribute zeros).
    rank : int
        Number of independent directions the data see.
    identifiable, unidentifiable : tuple of str
        A parameter is unidentifiable when it has a component in the null space.
    blind_spots : tuple of BlindSpot
    base_parameters : tuple of str
        A largest identifiable subset, chosen in `pivot_order` (frames first, then the
        first parameter of each blind group); the others can be held without losing any
        fit.
    indices : dict
        Observability indices of the base set's scaled Jacobian, with N poses and
        singular values s1 ≥ … ≥ sr: ``O1`` = (s1⋯sr)^(1/r) / √N (Borm & Menq), ``O2`` =
        s1/sr (condition number), ``O3`` = sr (minimum singular value), ``O4`` = sr²/s1
        (noise amplification, Nahvi & Hollerbach), ``O5`` = sr/s1 (inverse condition).
    column_norms : ndarray, shape (k,)
        The scaling: norm of each unscaled column, m per m or m per rad.
    n_poses : int
    """

    parameters: tuple[str, ...]
    singular_values: np.ndarray
    rank: int
    identifiable: tuple[str, ...]
    unidentifiable: tuple[str, ...]
    blind_spots: tuple[BlindSpot, ...]
    base_parameters: tuple[str, ...]
    indices: dict = field(default_factory=dict)
    column_norms: np.ndarray = field(default_factory=lambda: np.zeros(0))
    n_poses: int = 0

    @property
    def combinations(self) -> list[str]:
        """The blind spots in words, one sentence each."""
        return [b.text for b in self.blind_spots]

    @property
    def condition_number(self) -> float:
        """O2 of the base set (inf when nothing is identifiable)."""
        return self.indices.get("O2", float("inf"))

    def __str__(self) -> str:
        lines = [
            f"{len(self.parameters)} parameters, {self.n_poses} poses: rank {self.rank}",
            f"identifiable:   {', '.join(self.identifiable) or '(none)'}",
            f"unidentifiable: {', '.join(self.unidentifiable) or '(none)'}",
        ]
        lines += [f"  - {text}" for text in self.combinations]
        lines.append("indices: " + ", ".join(f"{k} = {v:.4g}" for k, v in self.indices.items()))
        return "\n".join(lines)


@with_one_blas_thread  # as `identify`: a study's truth analysis on a busy machine
def observability(
    robot: Robot, q, parameters=None, measurement="position", orientation_weight: float = 0.1
):
    """Which parameters a set of poses can identify, and which combinations it cannot.

    Parameters
    ----------
    robot : Robot
        The nominal robot (the Jacobian is taken at its parameters).
    q : array-like, shape (N, dof)
        Poses, rad (R) or m (P).
    parameters : str or list of str
        Names, families or ``"all"`` (see `casecal.model.parameters.select`). Default None: the
        paper's set θ, a, d.
    measurement : {"position", "pose"}
        What is measured at each pose: the tool point, or the tool point and the tool's
        orientation (full pose).
    orientation_weight : float
        For ``"pose"``: metres per radian that make an orientation error comparable to a
        position error (default 0.1: 1 mrad weighs like 0.1 mm).

    Returns
    -------
    Observability
    """
    if measurement not in ("position", "pose"):
        raise CalibrationError(
            f"measurement {measurement!r} is not supported; use 'position' or 'pose'"
        )
    q2, _ = check_joint_values(q, robot.dof)
    if measurement == "pose" and robot.is_tree:
        from ..model.kinematics import tree_refusal

        raise tree_refusal("orientation measurements (measurement='pose')")
    if measurement == "position":
        J, names = robot.position_jacobian(q2, selection(robot, parameters), deviations=True)
    else:
        J, names = robot.pose_jacobian(q2, selection(robot, parameters), deviations=True)
        J = np.concatenate([J[:, :3], orientation_weight * J[:, 3:]], axis=1)
    return analyse(J.reshape(-1, len(names)), names, n_poses=q2.shape[0])


def analyse(J: np.ndarray, names, n_poses: int, tolerance: float = RANK_TOLERANCE, prefer=()):
    """`observability` for a stacked Jacobian (rows: measurements, columns: `names`).

    `prefer` names parameters offered to the base set before all others, in its order: a
    fit that looks again where it ended keeps what it estimates and only adds what has
    become visible.
    """
    names = tuple(names)
    k = len(names)
    if J.shape[0] > k:
        # R of J = QR has the same column inner products (JᵀJ = RᵀR): every test below
        # (norms, SVD, null space, Gram-Schmidt, coefficients) gives the same on R, faster
        J = np.linalg.qr(J, mode="r")
    norms = np.linalg.norm(J, axis=0)
    zero = norms <= tolerance * max(norms.max(initial=0.0), np.finfo(float).tiny)
    Js = np.zeros_like(J)
    Js[:, ~zero] = J[:, ~zero] / norms[~zero]
    s, null = _svd_null(Js[:, ~zero], tolerance)  # null: (k_nonzero, r)
    s = np.concatenate([s, np.zeros(k - s.size)])  # zero columns add zero singular values
    s_max = s[0] if s.size else 0.0
    rank = int(np.sum(s > tolerance * s_max)) if s_max > 0 else 0

    live = [n for n, z in zip(names, zero, strict=True) if not z]
    # a parameter takes part in a blind direction where its share of the unit null vectors
    # is more than rounding of the near-dependency: at a fitted robot an exact dependency
    # (d2, d3 along parallel axes) is tilted a little and smears 1e-8 shares over every
    # parameter, which would name them all blind and lead the text with one of them
    support = np.where(np.abs(null) > NULL_SHARE, null, 0.0)
    blind_rows = _rref(support.T, 1e-9) if null.size else np.zeros((0, len(live)))
    spots = [_zero_column_spot(n) for n, z in zip(names, zero, strict=True) if z]
    spots += _group_spots(blind_rows, live, J[:, ~zero])
    unident = {m for spot in spots for m in spot.members}

    base = _base_parameters(Js, names, zero, rank, tolerance * s_max, prefer)
    return Observability(
        parameters=names,
        singular_values=s,
        rank=rank,
        identifiable=tuple(n for n in names if n not in unident),
        unidentifiable=tuple(n for n in names if n in unident),
        blind_spots=tuple(spots),
        base_parameters=base,
        indices=indices(Js[:, [names.index(b) for b in base]], n_poses),
        column_norms=norms,
        n_poses=n_poses,
    )


def indices(Js: np.ndarray, n_poses: int) -> dict:
    """O1 … O5 of a column-scaled Jacobian (definitions in `Observability`)."""
    s = np.linalg.svd(Js, compute_uv=False) if Js.size else np.zeros(0)
    if s.size == 0 or s[-1] <= 0:
        return {"O1": 0.0, "O2": float("inf"), "O3": 0.0, "O4": 0.0, "O5": 0.0}
    return {
        "O1": float(np.exp(np.mean(np.log(s))) / np.sqrt(n_poses)),
        "O2": float(s[0] / s[-1]),
        "O3": float(s[-1]),
        "O4": float(s[-1] ** 2 / s[0]),
        "O5": float(s[-1] / s[0]),
    }


def _svd_null(Js: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Singular values and a null-space basis (columns) of `Js`, from one thin SVD."""
    m, n = Js.shape
    if n == 0:
        return np.zeros(0), np.zeros((0, 0))
    # a thin SVD gives all n right singular vectors when m >= n; else ask for all of them
    _, s, Vt = np.linalg.svd(Js, full_matrices=m < n)
    s_full = np.zeros(n)
    s_full[: s.size] = s
    blind = s_full <= tolerance * s_full[0] if s_full[0] > 0 else np.ones(n, bool)
    return s, Vt[blind].T


def _rref(A: np.ndarray, tol: float) -> np.ndarray:
    """Reduced row echelon form: a sparse basis of the row space, groups kept apart."""
    A = A.astype(float).copy()
    rows, cols = A.shape
    r = 0
    for c in range(cols):
        if r == rows:
            break
        pivot = r + int(np.argmax(np.abs(A[r:, c])))
        if abs(A[pivot, c]) <= tol:
            continue
        A[[r, pivot]] = A[[pivot, r]]
        A[r] /= A[r, c]
        for i in range(rows):
            if i != r:
                A[i] -= A[i, c] * A[r]
        r += 1
    A[np.abs(A) <= tol] = 0.0
    return A[:r]


def _zero_column_spot(name: str) -> BlindSpot:
    return BlindSpot(
        members=(name,),
        blind=(name,),
        visible=None,
        text=f"{name}: its column is zero, it does not change what is measured at these poses",
    )


def _group_spots(rows: np.ndarray, names: list[str], J: np.ndarray) -> list[BlindSpot]:
    """Split blind directions into groups of parameters that share them, and describe each."""
    if rows.size == 0:
        return []
    support = rows != 0
    # union of rows that share a parameter: connected components
    groups: list[set[int]] = []
    for row in support:
        members = set(np.flatnonzero(row))
        merged = [g for g in groups if g & members]
        for g in merged:
            members |= g
            groups.remove(g)
        groups.append(members)
    spots = []
    for g in sorted(groups, key=min):
        idx = sorted(g)
        members = tuple(names[i] for i in idx)
        g_rows = rows[[bool(support[r][idx].any()) for r in range(rows.shape[0])]]
        # rows are in the scaled coordinates: convert to physical coefficients
        norms = np.linalg.norm(J[:, idx], axis=0)
        # a null vector is a *direction* δp (units of each member); the visible combination
        # is a *functional* Σ c_i δp_i (units lead / member): their units invert
        blind = tuple(_expression(row[idx] / norms, members, direction=True) for row in g_rows)
        visible, coeffs = None, None
        if len(idx) - len(g_rows) == 1:  # the group's columns are all parallel
            ref = J[:, idx[0]]
            coeffs = J[:, idx].T @ ref / (ref @ ref)
            visible = _expression(coeffs, members)
            text = (
                f"{', '.join(members)}: only {visible} is identifiable, "
                "not the parameters alone (their columns are parallel)"
            )
        else:
            what = "1 combination is" if len(g_rows) == 1 else f"{len(g_rows)} combinations are"
            text = f"{', '.join(members)}: {what} blind: " + "; ".join(blind)
        spots.append(
            BlindSpot(
                members, blind, visible, text, None if coeffs is None else tuple(coeffs.tolist())
            )
        )
    return spots


def _expression(coeffs: np.ndarray, members, direction: bool = False) -> str:
    """``p1 + c2·p2 …`` normalised so the first coefficient is 1, units on the others.

    For a functional (``direction=False``) a coefficient has units lead/member; for a
    direction in parameter space (a null vector, ``direction=True``) member/lead.
    """
    lead = int(np.flatnonzero(np.abs(coeffs) > 1e-12 * np.abs(coeffs).max())[0])
    coeffs = coeffs / coeffs[lead]
    ref_unit = unit(members[lead])
    terms = []
    for c, name in zip(coeffs, members, strict=True):
        if abs(c) <= 1e-9:
            continue
        sign = "-" if c < 0 else "+"
        mag = abs(c)
        u = unit(name)
        if abs(mag - 1.0) <= 1e-3 + 1e-8 and u == ref_unit:  # np.isclose(mag, 1, rtol=1e-3)
            term = name
        else:
            scale = (
                "" if u == ref_unit else (f" {u}/{ref_unit}" if direction else f" {ref_unit}/{u}")
            )
            term = f"{mag:.4g}{scale}·{name}"
        terms.append((sign, term))
    text = terms[0][1] if terms[0][0] == "+" else "-" + terms[0][1]
    for sign, term in terms[1:]:
        text += f" {sign} {term}"
    return text


FRAME_PREFIXES = ("base_", "point", "tool_")
"""Parameter families offered first to the base set, in this order (see `pivot_order`)."""


def pivot_order(names) -> list[int]:
    """The order in which parameters are offered to the base set: frames, then joints.

    The base frame, the measured points and the tool frame come first, then the joint
    parameters in canonical order. A frame parameter moves every measured point by the
    same rigid motion, so where a joint parameter duplicates it (θ1 and d1 with the base;
    the last link's θn, dn, an, αn with the tool point) the frame absorbs it exactly,
    not only to first order, and the joint parameter is held at its nominal value. The
    other way round, the last joint's θn would stand for a tool offset through the tiny
    lever of the tool's distance from its axis, which is nearly singular when the tool
    point sits on that axis.
    """
    first = [i for prefix in FRAME_PREFIXES for i, n in enumerate(names) if n.startswith(prefix)]
    return first + [i for i in range(len(names)) if i not in set(first)]


def _base_parameters(
    Js: np.ndarray, names, zero, rank: int, threshold: float, prefer=()
) -> tuple[str, ...]:
    """A largest independent subset of columns: QR with the pivot order fixed.

    Columns are offered in `pivot_order` (frames, then theta1, d1, a1, alpha1, …; the
    `prefer` ones first, in their order) and kept when their component orthogonal to the
    columns kept so far exceeds `threshold`,
    the rank's own cut-off (Gram-Schmidt, applied twice for stability). So the first
    parameter of each blind group is estimated and the later ones are held: a predictable
    choice, where LAPACK's largest-norm pivoting would pick among equal-norm scaled
    columns by rounding noise. Falls back to pivoted QR (geqp3) if the greedy pass
    disagrees with the SVD rank.
    """
    if rank == 0:
        return ()
    room = np.zeros((Js.shape[0], min(Js.shape)))  # the kept columns, filled in order
    chosen = []
    order = [names.index(n) for n in prefer]
    order += [i for i in pivot_order(names) if names[i] not in prefer]
    for i in order:
        if zero[i]:
            continue
        basis = room[:, : len(chosen)]  # orthonormal
        v = Js[:, i].copy()
        for _ in range(2):
            v -= basis @ (basis.T @ v)
        norm = np.linalg.norm(v)
        if norm > threshold and len(chosen) < room.shape[1]:
            room[:, len(chosen)] = v / norm
            chosen.append(names[i])
    if len(chosen) != rank:
        import scipy.linalg  # rarely needed, slow to import

        _, _, perm = scipy.linalg.qr(Js, mode="economic", pivoting=True)
        chosen = [names[i] for i in perm[:rank] if not zero[i]]
    return tuple(n for n in names if n in chosen)


@dataclass(frozen=True)
class Representation:
    """What the estimated parameters stand for once the others are held.

    Attributes
    ----------
    terms : dict of str to tuple of (str, float)
        Per estimated parameter e, the held parameters h whose effect it carries, with
        coefficient c (units of e per unit of h): e's estimate is that of
        ``e + Σ c·h``, the held h being at their hold values.
    misfit : dict of str to float
        Per held parameter, the part of its column that the estimated ones cannot
        reproduce, relative to its norm: 0 for a parameter that is exactly a combination
        of the estimated ones (blind), 1 for one unrelated to them (0 also for a zero
        column, which nothing needs to reproduce).
    """

    terms: dict
    misfit: dict

    def expression(self, name: str) -> str:
        """``name + c·h …`` in words, e.g. ``"d2 + d3 + d4"``; `name` alone when it
        carries nothing else."""
        pairs = self.terms.get(name, ())
        return _expression(np.array([1.0, *(c for _, c in pairs)]), [name, *(h for h, _ in pairs)])

    def combination(self, name: str, values: dict) -> float:
        """The value of `name`'s combination for parameter `values` (missing: 0)."""
        return values.get(name, 0.0) + sum(
            c * values.get(h, 0.0) for h, c in self.terms.get(name, ())
        )


REPRESENTED = 0.05
"""A held parameter whose column the estimated ones reproduce to within this fraction is
named in their combinations; beyond it the held parameter is its own, unestimated effect."""


def represent(
    J: np.ndarray, names, estimated, exclude=(), standard_errors=None, sizes=()
) -> Representation:
    """Express each held parameter's column by the estimated ones (least squares).

    Parameters
    ----------
    J : ndarray, shape (rows, k)
        Jacobian (weighted or not) of all `names`, or its R factor.
    names : sequence of str
    estimated : sequence of str
        A subset of `names`.
    exclude : sequence of str
        Held parameters to leave out of the combinations (held for the noise: their effect
        on the measured points is below it), unless `standard_errors` is given.
    standard_errors : dict of str to float, optional
        Of the estimates, SI. Then an `exclude`d parameter is named in an estimate's
        combination where a plausible deviation of it (`sizes`, by default `UNITS`: 2.5 mm,
        0.5°) moves that estimate by more than its standard error: d3 held for the noise
        beside d2 makes the d2 estimate d2 + d3, and stating it as d2 alone was off by 100
        standard errors.
    sizes : tuple of (str, float, float)
        The robot's own plausible deviations (`casecal.Robot.sizes`); () for `UNITS`'.
    """
    names = list(names)
    if J.shape[0] > J.shape[1]:
        J = np.linalg.qr(J, mode="r")
    est = [names.index(n) for n in estimated]
    held = [i for i in range(len(names)) if i not in set(est) and names[i] not in exclude]
    norms = np.linalg.norm(J, axis=0)
    terms: dict[str, list] = {names[i]: [] for i in est}
    misfit: dict[str, float] = {}
    if standard_errors is not None and est:
        noisy = [i for i in range(len(names)) if i not in set(est) and names[i] in exclude]
        _alias(J, names, est, noisy, standard_errors, terms, sizes)
    if not held:
        return Representation({k: tuple(v) for k, v in terms.items()}, misfit)
    B = J[:, est]
    b_norms = np.where(norms[est] > 0, norms[est], 1.0)
    for h in held:
        if norms[h] == 0 or not est:
            misfit[names[h]] = 0.0 if norms[h] == 0 else 1.0
            continue
        coef = np.linalg.lstsq(B / b_norms, J[:, h], rcond=None)[0] / b_norms
        rest = J[:, h] - B @ coef
        misfit[names[h]] = float(np.linalg.norm(rest) / norms[h])
        if misfit[names[h]] > REPRESENTED:
            continue
        for k, c in zip(est, coef, strict=True):
            # a term carrying under a millionth of the held column is rounding, and one
            # through which a plausible deviation of the held parameter moves the estimate
            # by less than a micrometre (microradian) is no meaning a user could act on
            if (
                abs(c) * norms[k] > 1e-6 * norms[h]
                and abs(c) * UNITS[unit(names[h])].generous > 1e-6
            ):
                terms[names[k]].append((names[h], float(c)))
    return Representation({k: tuple(v) for k, v in terms.items()}, misfit)


def _alias(J, names, est, noisy, standard_errors, terms, sizes=()) -> None:
    """Add to `terms` the parameters held for the noise that a plausible deviation of
    would move an estimate by more than its standard error (the least-squares alias
    ``(J_eᵀ J_e)⁻¹ J_eᵀ J_h``, exact for the linearised fit whatever J_e leaves of J_h)."""
    norms = np.linalg.norm(J, axis=0)
    b_norms = np.where(norms[est] > 0, norms[est], 1.0)
    B = J[:, est] / b_norms
    for h in noisy:
        if norms[h] == 0:
            continue
        coef = np.linalg.lstsq(B, J[:, h], rcond=None)[0] / b_norms
        size = facts_of(names[h], sizes).plausible
        for k, c in zip(est, coef, strict=True):
            if abs(c) * size > standard_errors.get(names[k], np.inf):
                terms[names[k]].append((names[h], float(c)))


def selection(robot: Robot, parameters) -> list[str]:
    """Resolve `parameters` for `robot`. Default: the paper's θ, a, d (a URDF robot: its
    joint origins), and the parameters of its error terms, which it carries to be
    estimated."""
    if parameters is None:
        own = [n for t in robot.terms for n in t.parameters]
        if robot.convention == "urdf":
            dotted = [n for n in robot.parameter_names if "." in n]
            return [n for n in robot.parameter_names if n in set(dotted) | set(own)]
        chosen = set(select(robot.parameter_names, list(DEFAULT_PARAMETERS))) | set(own)
        return [n for n in robot.parameter_names if n in chosen]
    return select(robot.parameter_names, parameters)
