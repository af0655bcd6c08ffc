"""Second answers that distances cannot rule out: the mirror image, and tilts off a plane.

Distances between points do not change when the whole point cloud moves rigidly, and not
when it is reflected either. For a spatial arm the mirror image of its tool points is
usually not the cloud of any robot near the estimate (a left hand is no right hand), so
the data have one minimum. The tool points of a planar arm lie (nearly) in a plane: its
mirror image is (nearly) the same cloud, realised by the same model with the opposite
small tilts out of the plane (α, β, tool_z flipped), and both fit the distances equally.
A fit that lands on either one, or stops on the symmetric point between them (where the
tilts are blind to first order, but not to second), can call a robot the wrong shape by
millimetres a success.

`second_answers` looks for such a second answer after a distance fit and turns what it
finds into a line of the answer audit:

- *the mirror*: the fitted robot's tool points (at the measured poses and across the joint
  ranges) reflected through their best plane, the model fitted to them (every asked-for
  parameter and the base frame free), then to the measured distances;
- *steps off a symmetric point*: when held parameters become visible a small step away
  from the fitted robot, the estimated parameters fitted again with each of them stepped
  1, 3 and 10 mrad (or mm) either way: the profile of the cost along what the fit could
  not see there.

A second answer that differs in shape from the estimate by more than the predicted error
(from the covariance) or the noise fails the check: when it fits the distances as well as
the estimate (within chance), the data cannot tell the two apart and the check names both,
and the difference joins the predicted error; when it fits better, the fit stopped short.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..model.parameters import unit
from ..model.robot import Robot
from .analysis import analyse
from .audit import CHI2_LEVEL, Check
from .rank import chi2_quantile
from .rounds import workspace_poses
from .shapes import aligned_difference, shape_prediction
from .solvers import SOLVERS

STEPS = (1e-3, 3e-3, 1e-2)
"""How far (rad or m) off a symmetric point the tilt probe steps: from well above rounding
to the largest tilts a nominal drawing could hide (0.6°)."""

MIRROR_ITERATIONS = 30
"""Evaluations the fit of the model to the reflected tool points may take: a realisable
mirror image is a few steps away (the reflection of a nearly planar cloud is nearly the
cloud); a spatial arm's is not reached in any number."""

MIRROR_MISS = 1e-3
"""RMS (m) by which the model may miss the reflected tool points and still be fitted to
the distances from there: beyond it the mirror image is no robot of this model near the
estimate (a spatial arm's chirality), and the fit to the distances would only climb back."""

PULL = 1e-4
"""Weight (m per m or rad) pulling the fit to the reflected points towards the estimate:
the model's blind directions (d1 against the base height, α of the last link against the
tool) would otherwise drift and show as differences that mean nothing; 1 mrad costs 0.1
µm, far below what realises a mirror image, and the fit to the distances polishes after."""

BASE = ("base_x", "base_y", "base_z", "base_rx", "base_ry", "base_rz")

NAME = "no mirror image fits as well"


@dataclass(frozen=True)
class Alternative:
    """A second robot the distances were tested against.

    Attributes
    ----------
    kind : {"mirror", "tilt"}
    robot : Robot
    cost : float
        Its distance cost ``0.5 Σ (w r)²``, in the fit's units.
    shape_rms, shape_max : float
        RMS and largest distance (m) between its tool points and the estimate's across the
        joint ranges, after the best rigid motion (distances see no frame).
    """

    kind: str
    robot: Robot
    cost: float
    shape_rms: float
    shape_max: float
    stepped: tuple[str, ...] = ()
    """Held parameters a tilt probe stepped (shown beside the estimated ones)."""


@dataclass(frozen=True)
class SecondAnswers:
    """What `second_answers` found.

    Attributes
    ----------
    check : Check
        The audit line (module doc).
    predicted_rms : float or None
        RMS shape error (m) across the joint ranges that the covariance predicts, with the
        difference to any second answer that fits the distances as well added in quadrature;
        None without joint limits to draw poses from.
    correction_rms : float
        RMS change of the shape (m) the fit made across the joint ranges.
    """

    check: Check
    predicted_rms: float | None
    correction_rms: float


def second_answers(
    make: Callable,
    fitted: Robot,
    nominal: Robot,
    names,
    estimated,
    cov: np.ndarray,
    *,
    q: np.ndarray,
    known: bool,
    dof: int,
    floor: float,
    noise_rms: float,
    method: str,
    max_iterations: int,
    tolerance: float,
) -> SecondAnswers:
    """Look for a mirror image or a tilt that fits the distances as well (module doc).

    Parameters
    ----------
    make : callable
        ``make(robot, names)``: the distance problem (weighted residuals and Jacobian of the
        deviations of `names`) at `robot`.
    fitted, nominal : Robot
        The fitted robot, and the nominal one (deviations are shown from it).
    names, estimated : sequence of str
        The asked-for and the estimated parameters.
    cov : ndarray, shape (k, k)
        Covariance of the `estimated` deviations (m², m·rad, rad²).
    q : ndarray, shape (N, dof)
        The measured poses.
    known : bool
        Whether the weights are 1/σ (costs in noise variances).
    dof : int
        Residual degrees of freedom.
    floor : float
        The cost at the rounding floor of the data.
    noise_rms : float
        σ when known, else the RMS residual, m.
    method, max_iterations, tolerance
        As the fit's (the one-shot ``"svd"`` refits with Gauss-Newton).
    """
    names, estimated = list(names), list(estimated)
    cost = _cost(make, fitted)
    q_work = workspace_poses(fitted)
    q_shape = q if q_work is None else q_work
    q_all = q if q_work is None else np.vstack([q, q_work])
    predicted = shape_prediction(fitted, q_shape, estimated, cov)
    scale = 1.0 if known else (2.0 * cost / dof if dof > 0 else 1.0)
    judge = _Scale(
        cost=cost,
        margin=0.5 * chi2_quantile(CHI2_LEVEL, 1) * scale + floor,
        scale=scale,
        floor=floor,
        known=known,
        allowed=max(predicted, noise_rms, 1e-9),
        predicted=predicted,
        n_rows=int(np.count_nonzero(make(fitted, []).w_flat)),
    )
    solve = _solver(make, method, max_iterations, tolerance)
    mirror, miss = _mirror(make, fitted, names, estimated, q_all, solve)
    found = [("mirror", mirror, ())]
    found += [("tilt", tilt, (n,)) for n, tilt in _tilts(make, fitted, names, estimated, solve)]
    options = [
        Alternative(
            kind, robot, _cost(make, robot), *aligned_difference(robot, fitted, q_shape), stepped
        )
        for kind, robot, stepped in found
        if robot is not None
    ]
    # second answers the data cannot reject add their difference to the predicted error
    spread = max((a.shape_rms for a in options if judge.equal(a)), default=0.0)
    total = float(np.hypot(predicted, spread)) if q_work is not None else None
    check = _verdict(judge, options, miss, nominal, fitted, estimated, q_shape)
    correction = aligned_difference(fitted, nominal, q_shape)[0]
    return SecondAnswers(check, total, correction)


@dataclass(frozen=True)
class _Scale:
    """How a fit of distance cost `cost` judges its second answers."""

    cost: float
    margin: float  # a cost difference within chance, in the cost's units
    scale: float  # one noise (or residual) variance, in the cost's units
    floor: float
    known: bool
    allowed: float  # m RMS: a shape difference within the prediction or the noise
    predicted: float  # m RMS
    n_rows: int

    def equal(self, alt: Alternative) -> bool:
        return alt.cost <= self.cost + self.margin

    def matters(self, alt: Alternative) -> bool:
        return alt.shape_rms > self.allowed


def _verdict(judge: _Scale, options, miss, nominal, fitted, estimated, q) -> Check:
    """The audit line for the second answers `options` (module doc); `miss`: by how much
    the model missed the reflected points (m RMS)."""
    for alt in sorted(options, key=lambda a: a.cost):
        if judge.matters(alt) and judge.equal(alt):
            values = _values(nominal, fitted, alt.robot, [*estimated, *alt.stepped], q)
            return Check(NAME, False, _failed(judge, alt, values))
    said = []
    if not np.isfinite(miss) and not options:
        return Check(NAME, None, "the model could not be fitted to the mirror image of its points")
    if MIRROR_MISS < miss < np.inf:
        said.append(
            "no robot of this model near the estimate realises the mirror image of its tool "
            f"points (the closest misses them by {miss * 1e3:.3g} mm RMS)"
        )
    apart = [a for a in options if judge.matters(a)]
    if apart:
        best = min(apart, key=lambda a: a.cost)
        what = "mirror image" if best.kind == "mirror" else "step off the estimate"
        if judge.known:
            worse = (
                f"{(best.cost - judge.cost) / judge.scale:.3g} noise variances worse (chance: "
                f"up to {judge.margin / judge.scale:.3g})"
            )
        else:  # unweighted: the cost is half the sum of squared residuals, m²
            worse = (
                f"to {np.sqrt(2 * best.cost / judge.n_rows) * 1e3:.3g} mm RMS, the estimate "
                f"to {np.sqrt(2 * judge.cost / judge.n_rows) * 1e3:.3g} mm"
            )
        said.append(f"the best {what} that differs in shape fits these distances {worse}")
    if not said:
        said.append(
            "the mirror image of the fitted tool points is the fitted robot itself, within "
            f"the predicted error of {judge.predicted * 1e3:.2g} mm or the noise"
        )
    return Check(NAME, True, "; ".join(said))


def _failed(judge: _Scale, alt: Alternative, values: str) -> str:
    """What a failing line says of `alt`, a second answer as good as the estimate or
    better, whose parameters `values` shows."""
    unit = "noise variances" if judge.known else "residual variances"
    gap = (alt.cost - judge.cost) / judge.scale
    chance = f"chance: up to {judge.margin / judge.scale:.3g}"
    differ = (
        f"they differ by up to {alt.shape_max * 1e3:.3g} mm ({alt.shape_rms * 1e3:.3g} mm "
        f"RMS) across the workspace, against a predicted error of {judge.predicted * 1e3:.2g} mm"
    )
    if alt.cost < judge.cost - judge.margin:
        text = (
            f"{values} fits these distances better ({-gap:.3g} {unit} lower, {chance}); "
            f"{differ}: the fit stopped short of the best answer (a planar arm's fit stops "
            "on the flat point, where the tilts out of its plane are blind to first order "
            "but not to second)"
        )
    else:
        if max(alt.cost, judge.cost) <= judge.floor:
            how = "both to the rounding floor of the data"
        else:
            how = f"costs {abs(gap):.2g} {unit} apart, {chance}"
        what = "the mirror image" if alt.kind == "mirror" else "a step off the estimate"
        text = (
            f"{what}: {values} fit these distances equally ({how}); {differ}: the error is "
            f"at least {alt.shape_rms * 1e3:.3g} mm RMS"
        )
    return text + (
        ". Distances are the same for a robot and its mirror image, and a planar arm's "
        "mirror image is the same arm tilted the other way: they cannot tell which way its "
        "plane of motion tilts (measure some positions, e.g. with a tracker, to tell them "
        "apart; or, if the arm is known to move in a flat plane, leave the tilts out of it "
        "(alpha*, beta*, tool_z) out of --parameters)"
    )


def _cost(make, robot: Robot) -> float:
    r = make(robot, []).residual(np.zeros(0))
    return 0.5 * float(r @ r)


def _solver(make, method, max_iterations, tolerance):
    """Fit `names` of a robot to the distances from where it is: the fit's own method (a
    second answer is a second minimum, which one linearisation does not reach)."""
    solver = SOLVERS["gauss-newton" if method == "svd" else method]

    def solve(robot: Robot, names) -> Robot:
        problem = make(robot, list(names))
        x = solver(
            problem, np.zeros(len(names)), max_iterations=max_iterations, tolerance=tolerance
        )[0]
        return problem.robot_at(x)

    return solve


def _free(make, robot: Robot, names, prefer) -> list[str]:
    """The base set of `names` at `robot`, `prefer` offered first."""
    J = make(robot, list(names)).jacobian(np.zeros(len(names)))
    return list(analyse(J, names, J.shape[0], prefer=list(prefer)).base_parameters)


def _tilts(make, fitted: Robot, names, estimated, solve) -> list[tuple[str, Robot]]:
    """The estimated parameters fitted again with each held parameter that a step off
    `fitted` makes visible set a step away (`STEPS`, both signs): the profile of the cost
    along the directions a symmetric point hides. None such when `fitted` is no symmetric
    point (nothing held becomes visible)."""
    held = [n for n in names if n not in estimated]
    if not held:
        return []
    signs = np.random.default_rng(0).choice([-1.0, 1.0], len(held))
    step = dict(zip(held, (STEPS[0] * signs).tolist(), strict=True))
    free = _free(make, fitted.with_deviations(step), names, estimated)
    return [
        (n, solve(fitted.with_deviations({n: sign * size}), estimated))
        for n in free
        if n not in estimated
        for size in STEPS
        for sign in (1.0, -1.0)
    ]


def _mirror(
    make, robot: Robot, names, estimated, q: np.ndarray, solve
) -> tuple[Robot | None, float]:
    """The model fitted to `robot`'s tool points at `q` reflected through their best plane
    (positions, every asked-for parameter and the base frame free: what realises the
    mirror may be a parameter the distances see only at second order), then to the
    distances (the base set there, `estimated` first). None when the model misses the
    reflected points by more than `MIRROR_MISS`; and by how much it missed them (m RMS)."""
    p = robot.position(q)
    centre = p.mean(axis=0)
    normal = np.linalg.svd(p - centre, full_matrices=False)[2][-1]
    target = p - 2.0 * np.outer((p - centre) @ normal, normal)
    frame = [n for n in BASE if n in robot.parameter_names and n not in names]
    moved = _fit_points(robot, [*names, *frame], q, target)
    if moved is None:
        return None, float("inf")
    miss = float(np.sqrt(np.mean(np.sum((moved.position(q) - target) ** 2, axis=1))))
    if miss > MIRROR_MISS:
        return None, miss
    return solve(moved, _free(make, moved, names, estimated)), miss


def _fit_points(robot: Robot, names, q, target) -> Robot | None:
    """Least-squares fit of the deviations of `names` so that ``robot.position(q)`` meets
    `target` (N, 3), pulled weakly to zero (`PULL`); None when it fails."""
    from scipy.optimize import least_squares  # scipy loads slowly; only fits need it

    def at(x):
        return robot.with_deviations(dict(zip(names, x.tolist(), strict=True)))

    def residual(x):
        return np.concatenate([(at(x).position(q) - target).ravel(), PULL * x])

    def jacobian(x):
        J = at(x).position_jacobian(q, list(names))[0].reshape(-1, len(names))
        return np.vstack([J, PULL * np.eye(len(names))])

    try:
        out = least_squares(
            residual,
            np.zeros(len(names)),
            jac=jacobian,
            method="lm",
            x_scale="jac",
            max_nfev=MIRROR_ITERATIONS,
        )
    except (ValueError, np.linalg.LinAlgError):
        return None
    return at(out.x) if np.all(np.isfinite(out.x)) else None


def _values(nominal: Robot, a: Robot, b: Robot, names, q, most: int = 3) -> str:
    """``"alpha1 = +1.22 mrad or −1.22 mrad from nominal"`` for those of `names` whose
    change moves the tool points most (angles weighted by the reach of the points), tilts
    (α, β) first: they are what a mirror image flips. `names`: the estimated parameters
    (and any a probe stepped); the held ones move along blind directions, where any value
    fits and says nothing."""
    p = a.position(q)
    reach = float(np.max(np.linalg.norm(p - p.mean(axis=0), axis=1)))
    pa, pb, p0 = a.parameters, b.parameters, nominal.parameters
    angle = {n: unit(n) == "rad" for n in names}  # a URDF origin's roll … offset too
    weight = {n: abs(pb[n] - pa[n]) * (reach if angle[n] else 1.0) for n in names}
    largest = max(weight.values(), default=0.0)
    order = sorted(names, key=lambda n: (not n.startswith(("alpha", "beta")), -weight[n]))
    top = [n for n in order if weight[n] > 0.01 * largest][:most]

    def shown(n, v):
        return f"{(v - p0[n]) * 1e3:+.3g} {'mrad' if angle[n] else 'mm'}".replace("-", "−")

    parts = [f"{n} = {shown(n, pa[n])} or {shown(n, pb[n])}" for n in top]
    return ", ".join(parts) + " from nominal"
