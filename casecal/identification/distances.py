"""Relative measurements: distances between the tool points of two poses.

A ball bar, a calibrated plate or a pair of points a known distance apart measures
``|f(q_i) - f(q_j)|`` without any external frame. Distances do not change when everything
moves rigidly, so the base frame cannot be seen; what else becomes blind is left to the
identifiability analysis of the distance Jacobian ``uᵀ (J_i - J_j)`` (u the unit vector
from one point to the other), not assumed.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from functools import partial

import numpy as np

from ..data.units import distances_at_the_door
from ..design.poses import rng_from
from ..errors import CalibrationError
from ..model.robot import Robot, check_joint_values
from .analysis import analyse, represent, selection
from .audit import Audit, Facts, audit, smoothness
from .calibration import Calibration
from .distance_problem import DistanceProblem
from .evidence import outside_gain, still_joints
from .fitting import check_iterations, rms_of, shared_problems, verdict
from .linalg import gauss_newton_step
from .mirror import second_answers
from .rank import held_gain
from .rounds import Settings, fit_in_rounds, workspace_poses
from .solvers import ROUNDING, SOLVERS, floor_cost
from .uncertainty import uncertainty


@dataclass(frozen=True)
class DistanceMeasurements:
    """Measured distances between the tool points of pairs of poses.

    Attributes
    ----------
    q : ndarray, shape (N, dof)
        Poses, rad (R) or m (P).
    pairs : ndarray of int, shape (P, 2)
        0-based pose indices of each measured pair.
    distances : ndarray, shape (P,)
        Measured distances, m.
    sigma : ndarray, shape (P,)
        Their noise σ, m (0: unknown / noise-free).
    """

    q: np.ndarray
    pairs: np.ndarray
    distances: np.ndarray
    sigma: np.ndarray

    def __post_init__(self) -> None:
        q, _ = check_joint_values(self.q, np.shape(self.q)[-1] if np.ndim(self.q) else 0)
        pairs = np.asarray(self.pairs)
        if pairs.ndim != 2 or pairs.shape[1] != 2 or len(pairs) == 0:
            raise CalibrationError("pairs must have shape (P, 2), P >= 1: two pose indices each")
        if not np.issubdtype(pairs.dtype, np.integer):
            raise CalibrationError("pair indices must be integers")
        if pairs.min() < 0 or pairs.max() >= len(q) or np.any(pairs[:, 0] == pairs[:, 1]):
            raise CalibrationError(
                f"pair indices must name two different poses among 0 … {len(q) - 1}"
            )
        try:
            d = np.asarray(self.distances, dtype=float)
            sigma_in = np.asarray(self.sigma, dtype=float)
        except (TypeError, ValueError):
            raise CalibrationError("distances and sigma must be numbers (m)") from None
        if d.shape != (len(pairs),) or not np.all(np.isfinite(d)) or np.any(d < 0):
            raise CalibrationError("distances must be one finite, non-negative value per pair (m)")
        try:
            sigma = np.broadcast_to(sigma_in, d.shape).copy()
        except ValueError:
            raise CalibrationError("distance sigma must be one value or one per pair (m)") from None
        if not np.all(np.isfinite(sigma)) or np.any(sigma < 0):
            raise CalibrationError("distance sigma must be finite and non-negative (m)")
        for name, value in (
            ("q", q),
            ("pairs", pairs.astype(int)),
            ("distances", d),
            ("sigma", sigma),
        ):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n_pairs(self) -> int:
        """Number of measured distances P."""
        return len(self.distances)


def random_pairs(n_poses: int, n_pairs: int, seed=0) -> np.ndarray:
    """`n_pairs` distinct pairs of different poses, (n_pairs, 2)."""
    if not all(
        isinstance(v, int | np.integer) and not isinstance(v, bool) for v in (n_poses, n_pairs)
    ):
        raise CalibrationError("n_poses and n_pairs must be integers")
    rng = rng_from(seed)
    all_pairs = np.array([(i, j) for i in range(n_poses) for j in range(i + 1, n_poses)])
    if n_pairs > len(all_pairs):
        raise CalibrationError(f"{n_poses} poses have only {len(all_pairs)} pairs")
    return all_pairs[rng.choice(len(all_pairs), n_pairs, replace=False)]


def simulate_distances(true_robot: Robot, q, pairs, noise=0.0, seed=None) -> DistanceMeasurements:
    """Distances between the tool points of `pairs` of poses of `true_robot`, with noise σ (m)."""
    q2, _ = check_joint_values(q, true_robot.dof)
    if true_robot.is_tree:
        from ..model.kinematics import tree_refusal

        raise tree_refusal("distance measurements")
    pairs = np.asarray(pairs)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or not np.issubdtype(pairs.dtype, np.integer):
        raise CalibrationError("pairs must be integer pose indices of shape (P, 2)")
    if pairs.min() < 0 or pairs.max() >= len(q2):
        raise CalibrationError(f"pair indices must lie in 0 … {len(q2) - 1}")
    p = true_robot.position(q2)
    d = np.linalg.norm(p[pairs[:, 0]] - p[pairs[:, 1]], axis=1)
    if noise:
        d = d + rng_from(seed).normal(scale=noise, size=d.shape)
    return DistanceMeasurements(q2, pairs, np.abs(d), noise)


def read_distance_csv(poses_path, pairs_path, robot: Robot) -> DistanceMeasurements:
    """Read poses (joint columns as in `casecal.read_csv`) and pairs (``i, j, distance_mm``,
    optional ``sigma_mm``; i and j are 0-based rows of the poses file)."""
    from ..data.files import _numbers, read_joints, read_table  # pandas: files only

    poses_df, poses_label = read_table(poses_path)
    q = read_joints(poses_df, robot, poses_label)
    df, label = read_table(pairs_path)
    for col in ("i", "j", "distance_mm"):
        if col not in df:
            raise CalibrationError(f"{label}: missing column {col!r}; pairs need i, j, distance_mm")
    ij = np.column_stack([_numbers(df, "i", label), _numbers(df, "j", label)])
    if np.any(ij != np.round(ij)):
        raise CalibrationError(f"{label}: i and j must be whole row numbers of the poses file")
    sigma = _numbers(df, "sigma_mm", label) * 1e-3 if "sigma_mm" in df else 0.0
    return DistanceMeasurements(q, ij.astype(int), _numbers(df, "distance_mm", label) * 1e-3, sigma)


def write_distance_csv(pairs_path, measurements: DistanceMeasurements) -> None:
    """Write the pairs file (i, j, distance_mm, sigma_mm)."""
    import pandas as pd

    from ..data.files import write_atomic

    df = pd.DataFrame(
        {
            "i": measurements.pairs[:, 0],
            "j": measurements.pairs[:, 1],
            "distance_mm": measurements.distances * 1e3,
            "sigma_mm": measurements.sigma * 1e3,
        }
    )
    write_atomic(pairs_path, df.to_csv(index=False, float_format="%.17g", lineterminator="\n"))


def identify_distances(
    robot: Robot,
    measurements: DistanceMeasurements,
    parameters=None,
    method: str = "gauss-newton",
    max_iterations: int = 100,
    tolerance: float = 1e-10,
    truth: dict | None = None,
    progress=None,
) -> Calibration:
    """Identify parameter deviations from distances between tool points (see module doc).

    Same methods, treatment of blind parameters and result type as `casecal.identify`;
    `Calibration.residuals` has one row per pair (distance residual, m).
    """
    t0 = time.perf_counter()
    if robot.is_tree:
        from ..model.kinematics import tree_refusal

        raise tree_refusal("distance measurements")
    if method not in SOLVERS or method == "ipopt":
        raise CalibrationError("distance identification supports svd, gauss-newton and lm")
    names = selection(robot, parameters)
    if measurements.q.shape[1] != robot.dof:
        raise CalibrationError(
            f"poses have {measurements.q.shape[1]} joints; robot has {robot.dof}"
        )
    distances_at_the_door(robot, measurements.q, measurements.pairs, measurements.distances)
    if robot.coupling is not None:  # the model alone, in its joints (`casecal.identify`)
        model = dataclasses.replace(measurements, q=robot.model_joints(measurements.q))
        cal = identify_distances(
            robot.uncoupled(), model, parameters, method, max_iterations, tolerance, truth,
            progress,
        )  # fmt: skip
        return dataclasses.replace(
            cal,
            nominal=robot,
            robot=cal.robot.recoupled(robot),
            still_joints=still_joints(measurements.q, robot),
        )
    known = bool(np.all(measurements.sigma > 0))
    if not known and np.any(measurements.sigma > 0):
        raise CalibrationError(
            "distance sigma is zero for some pairs and not others; give every pair its "
            "sigma (> 0), or none (0 everywhere) to weigh all alike"
        )
    w = 1.0 / measurements.sigma if known else np.ones(measurements.n_pairs)
    max_iterations, tolerance = check_iterations(max_iterations, tolerance)
    make = shared_problems(_maker(measurements.q, measurements.pairs, measurements.distances, w))
    full = make(robot, names)
    r0, J0 = measured_rows(full, np.zeros(len(names)))
    obs = analyse(J0, names, measurements.n_pairs)
    if obs.rank >= measurements.n_pairs and len(names) > obs.rank:
        raise CalibrationError(
            f"{measurements.n_pairs} distances are fewer than the {len(names)} parameters asked "
            "for, so they cannot tell which are blind; measure more pairs"
        )
    if not obs.base_parameters:
        raise CalibrationError("none of the asked-for parameters changes a measured distance")
    # distances' own ways (`Settings`): no damped crawl where a round stalls, frames no first
    settings = Settings(
        method,
        max_iterations,
        tolerance,
        known,
        full.w,
        progress=progress,
        damped_after_stall=False,
        frames_first=False,
    )
    fit = fit_in_rounds(make, robot, names, settings, rms_of(full, len(names)))
    problem = make(fit.robot, list(fit.estimated))
    full_end = make(fit.robot, names)
    end = full_end.reduced(np.zeros(len(names)))  # where the fit ended, every asked-for column
    x0 = np.zeros(len(fit.estimated))
    r, J = measured_rows(problem, x0)
    cov, se = uncertainty(J, r, known, names, fit.estimated)
    deviations = fit.robot.deviations_from(robot, names)  # rotations: not differences
    outside = [n for n in robot.parameter_names if n not in names]
    unasked = outside_gain(make(fit.robot, [*fit.estimated, *outside]), fit.estimated)
    q_pairs = np.hstack(
        [measurements.q[measurements.pairs[:, 0]], measurements.q[measurements.pairs[:, 1]]]
    )
    floor = floor_cost(problem, ROUNDING)
    # distances cannot see a reflection: a planar arm's mirror image fits them too
    second = second_answers(
        make,
        fit.robot,
        robot,
        names,
        fit.estimated,
        cov,
        q=measurements.q,
        known=known,
        dof=r.size - len(fit.estimated),
        floor=floor,
        noise_rms=float(np.mean(measurements.sigma) if known else np.sqrt(np.mean((r / w) ** 2))),
        method=method,
        max_iterations=max_iterations,
        tolerance=tolerance,
    )
    checks = audit(
        Facts(
            solver_status=fit.solver_status,
            solver_message=fit.message,
            cost_start=0.5 * float(r0 @ r0),
            cost_final=0.5 * float(r @ r),
            floor=floor,
            predicted_decrease=gauss_newton_step(J, r)[1],
            known=known,
            dof=r.size - len(fit.estimated),
            rms_start=float(np.sqrt(np.mean((r0 / w) ** 2))),
            rms_final=float(np.sqrt(np.mean((r / w) ** 2))),
            settled=fit.settled,
            rounds=fit.rounds,
            predicted_rms=second.predicted_rms,
            correction_rms=second.correction_rms,
            noise_rms=float(np.mean(measurements.sigma)),
            prediction_note="no joint limits to draw poses from",
            one_shot=method == "svd",
            n_points=r.size,
            n_estimated=len(fit.estimated),
            smoothness=smoothness(q_pairs, r / w),
            items="pairs",
            outside_gain=unasked.gain,
            outside_visible=unasked.n_visible,
            outside_leading=unasked.leading,
            blind_here=_blind_only_here(
                robot if method == "svd" else fit.robot, names, fit.estimated, fit.pruned
            ),
            still=still_joints(measurements.q, robot),
            unsupported=fit.unsupported,
            held=tuple(fit.pruned),
            held_gain=held_gain(end, names, fit.estimated, fit.pruned) if fit.pruned else 0.0,
        )
    )
    checks = Audit((*checks.checks, second.check))
    status, message = verdict(checks, fit.solver_status, fit.message)
    if second.check.passed is False:
        # the second answer explains a prediction that fails with it: name it first
        others = [c.name for c in checks.failures if c is not second.check]
        also = f" (also failed: {', '.join(others)})" if others else ""
        message = f"failed the answer audit: {second.check.name}: {second.check.text}{also}"
    at_end = measured_rows(full_end, np.zeros(len(names)))[1]
    cal = Calibration(
        method=method,
        nominal=robot,
        robot=fit.robot,
        parameters=tuple(names),
        estimated=tuple(fit.estimated),
        deviations=deviations,
        standard_errors=se,
        covariance=cov,
        residuals=(r / w)[:, None],
        residuals_before=(r0 / w)[:, None],
        iterations=fit.iterations,
        status=status,
        message=message,
        history=fit.history,
        observability=fit.end_analysis,
        sigma_known=known,
        wall_time=time.perf_counter() - t0,
        audit=checks,
        solver_status=fit.solver_status,
        representation=represent(at_end, names, fit.estimated),
        start_observability=obs,
        rounds=fit.rounds,
        joined=tuple(n for n in fit.estimated if n not in obs.base_parameters),
        pruned=fit.pruned,
        frozen=fit.frozen,
        measured="distances",
        start_note=_flat_note(robot, names),
    )
    return cal.compare_to(truth) if truth is not None else cal


FLAT = 1e-6
"""RMS distance (m) of a robot's tool points from their best plane, across its joint
ranges, under which it moves in a plane."""


def _flat_note(robot: Robot, names) -> str:
    """Words for a planar arm whose tilts out of its plane were not asked for: distances see
    them at second order only, so the fit takes the arm to be flat; else ""."""
    unasked = [n for n in robot.parameter_names if n.startswith(("alpha", "beta"))]
    unasked = [n for n in unasked if n not in names]
    q_work = workspace_poses(robot)
    if not unasked or q_work is None:
        return ""
    p = robot.position(q_work)
    thickness = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)[-1] / np.sqrt(len(p))
    if thickness > FLAT:
        return ""
    return (
        f"The arm moves in a plane, and its tilts out of it ({', '.join(unasked[:4])}"
        f"{' …' if len(unasked) > 4 else ''}) were not asked for: distances see them at second "
        "order only, so this fit takes the arm to be flat. If it may not be (a tilt of 1 mrad "
        "moves a 1 m arm's tool 1 mm out of its plane, which no residual here shows), ask "
        "for all parameters (the fit then says whether the distances can tell) or measure "
        "some positions."
    )


WORKSPACE_PAIRS = 800
"""Pairs among the workspace poses on which `_blind_only_here` looks."""


def _blind_only_here(robot: Robot, names, estimated, pruned=()) -> tuple[str, ...]:
    """Asked-for parameters the measured pairs cannot tell from the estimated ones but
    pairs across the joint ranges would (a joint that never moved): the distance twin of
    `casecal.identification.evidence.blind_only_here`. Without joint limits, none. Those
    held because the noise hides them (`pruned`) are not blind: the held-parameter check
    judges them."""
    held = [n for n in names if n not in estimated and n not in pruned]
    q_work = workspace_poses(robot)
    if q_work is None or not held:
        return ()
    pairs = random_pairs(len(q_work), WORKSPACE_PAIRS, seed=0)
    ones = np.ones(len(pairs))  # distances unused: the Jacobian only
    work = _maker(q_work, pairs, ones, ones)(robot, names=names)
    J = measured_rows(work, np.zeros(len(names)))[1]
    elsewhere = analyse(J, names, len(pairs), prefer=list(estimated)).base_parameters
    return tuple(n for n in held if n in elsewhere)


def _maker(q, pairs, distances, w):
    """``make(robot, names, kernel_names=None, memo=None)`` of the `DistanceProblem` of
    `distances` (P,) m between the tool points of `pairs` (P, 2) of poses `q`, weights
    `w` (P,) 1/m."""
    y = np.zeros((len(pairs), 1, 3))
    y[:, 0, 0] = distances
    weights = np.zeros((len(pairs), 3))
    weights[:, 0] = w
    return partial(DistanceProblem, q=q[pairs[:, 0]], y=y, w=weights, poses=q, pairs=pairs)


def measured_rows(problem: DistanceProblem, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted residuals (P,) and Jacobian (P, k) of the distances alone (the rows a
    `DistanceProblem` carries for the coordinates it does not measure left out)."""
    n = len(problem.q)
    r = problem.residual(x).reshape(n, 3)[:, 0]
    return r, problem.jacobian(x).reshape(n, 3, -1)[:, 0]
