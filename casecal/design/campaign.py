"""Calibrate until good enough: measure poses in batches until the predicted error is small.

The paper's conclusion asks for "a particular threshold value for sufficient calibration"
reached with "a minimum number of pose measurements". `calibrate_until` adds poses in
batches (D-optimal given those already measured, or in the paper's order, or uniform),
identifies after each batch, and predicts the position error the calibrated robot will
make on poses it was not fitted to, from the covariance of the estimate. It stops when
that prediction is under the threshold.

The prediction covers what measurement noise leaves in the parameters; each held-out
pose's error is Gaussian with covariance ``J C Jᵀ``, and the predicted error is the 95th
percentile over 200 uniform held-out poses of that error's 95 % radius. A fit whose
residuals exceed the stated noise (reduced χ² > 1: a wrong model, a wrong frame, an
outlier) inflates the prediction accordingly, so it cannot claim the threshold.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..data.measurements import Measurements
from ..errors import CalibrationError
from ..identification.calibration import Calibration
from ..identification.fit import identify
from ..model.robot import Robot
from . import poses

ORDERS = ("optimal", "seed", "uniform")


@dataclass(frozen=True)
class Campaign:
    """How a calibrate-until-good-enough run went.

    Attributes
    ----------
    calibration : Calibration
        The last identification.
    measurements : Measurements
        Everything measured.
    predicted : float
        Predicted 95 % position error on held-out poses at the end, m.
    history : tuple of (int, float)
        (poses measured, predicted error in m) after each batch.
    reached : bool
        Whether the prediction went under the threshold.
    threshold : float
        m.
    """

    calibration: Calibration
    measurements: Measurements
    predicted: float
    history: tuple[tuple[int, float], ...]
    reached: bool
    threshold: float

    @property
    def n_poses(self) -> int:
        """Poses measured."""
        return self.measurements.n_poses

    def __str__(self) -> str:
        state = "reached" if self.reached else "NOT reached"
        steps = ", ".join(f"{n}: {e * 1e3:.3f}" for n, e in self.history)
        return (
            f"threshold {self.threshold * 1e3:g} mm {state} with {self.n_poses} poses; "
            f"predicted 95 % error (mm) after each batch: {steps}"
        )


_Z = np.random.default_rng(20261122).normal(size=(4000, 3))  # fixed: predictions repeat


def predicted_error(cal: Calibration, q_holdout: np.ndarray, level: float = 0.95) -> float:
    """The `level` percentile over `q_holdout` of each pose's `level` error radius, m (a
    tree's: of each tip's at each pose).

    A pose's error is Gaussian with covariance ``J C Jᵀ`` (anisotropic in general); its
    radius quantile is taken from 4,000 fixed standard-normal samples through the
    eigenvalues. `C` is inflated by the fit's reduced χ² when that exceeds 1, so a model
    that does not fit its data cannot promise a small error.
    """
    # new poses in the first session's frame (`cal.robot`'s): the later sessions' frames
    # move none of them, so their rows and columns of the covariance drop out
    own = [k for k, n in enumerate(cal.estimated) if n in cal.robot.parameters]
    names = [cal.estimated[k] for k in own]
    J, _ = cal.robot.position_jacobian(q_holdout, names, deviations=True)
    J = J.reshape(-1, 3, J.shape[-1])  # a tree's rows per tip: each tip's error its own
    C = np.asarray(cal.covariance)[np.ix_(own, own)]
    cov = np.einsum("nik,kl,njl->nij", J, C, J)  # (N, 3, 3)
    lam = np.clip(np.linalg.eigvalsh(cov), 0.0, None)  # (N, 3)
    radius = np.quantile(np.sqrt((_Z**2) @ lam.T), level, axis=0)  # (N,)
    chi2 = cal.reduced_chi2
    return float(np.quantile(radius, level)) * np.sqrt(max(1.0, 0.0 if np.isnan(chi2) else chi2))


def calibrate_until(
    robot: Robot,
    measure: Callable[[np.ndarray], Measurements],
    threshold: float = 0.1e-3,
    *,
    batch: int = 5,
    max_poses: int = 300,
    order: str = "optimal",
    parameters=None,
    method: str = "gauss-newton",
    candidates=None,
    seed: int = 0,
) -> Campaign:
    """Measure poses in batches until the predicted held-out error is under `threshold`.

    Parameters
    ----------
    robot : Robot
        Nominal robot.
    measure : callable(q (n, dof)) -> Measurements
        Measures the requested poses (a simulation, or the lookup of a pool of measured
        poses, see `pool_measure`). Its σ weights the fit and the prediction.
    threshold : float
        Predicted 95 % position error to reach, m (default 0.1 mm).
    batch : int
        Poses added per round.
    max_poses : int
        Stop here even if the threshold was not reached.
    order : {"optimal", "seed", "uniform"}
        D-optimal poses given those already measured (from `candidates`), the paper's
        schedule in its order, or uniform poses.
    parameters, method
        As for `casecal.identify` (default: the paper's θ, a, d; Gauss-Newton).
    candidates : array-like, shape (C, dof), optional
        Poses that can be measured (default 2000 uniform).
    seed : int

    Returns
    -------
    Campaign
    """
    from ..identification.analysis import selection
    from ..identification.fit import METHODS

    if order not in ORDERS:
        raise CalibrationError(f"order must be one of {', '.join(ORDERS)}, got {order!r}")
    if method not in METHODS:
        raise CalibrationError(f"unknown method {method!r}; use one of {', '.join(METHODS)}")
    selection(robot, parameters)  # a bad selection fails now, before anything is measured
    if not isinstance(threshold, int | float) or not (threshold > 0 and np.isfinite(threshold)):
        raise CalibrationError(f"threshold must be a positive length in m, got {threshold!r}")
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in (batch, max_poses, seed)):
        raise CalibrationError("batch, max_poses and seed must be integers")
    if batch < 1 or max_poses < batch or seed < 0:
        raise CalibrationError("batch must be >= 1, max_poses >= batch and seed >= 0")
    cand = (
        poses.uniform(robot, 2000, seed=seed)
        if candidates is None
        else np.asarray(candidates, float)
    )
    unused = np.ones(len(cand), bool)  # a pose is measured once: repeats would fake data
    q_hold = poses.uniform(robot, 200, seed=seed + 1)
    k = len(selection(robot, parameters))  # the default's as `identify` takes it (a URDF's)
    n = max(batch, -(-k // 3) + 1)  # the first round must be able to identify something
    q = np.zeros((0, robot.dof))
    meas, cal, history, pred = None, None, [], np.inf
    rng = np.random.default_rng(seed + 2)
    schedule = poses.seed_schedule(robot, max_poses)
    while True:
        n_new = min(n - len(q), max_poses - len(q))
        if order == "seed":
            new = schedule[len(q) : len(q) + n_new]
        else:
            free = np.flatnonzero(unused)
            if len(free) < n_new:
                break  # the candidates are used up
            if order == "optimal":
                new = poses.optimal(
                    robot,
                    n_new,
                    candidates=cand[free],
                    parameters=parameters,
                    include=q if len(q) else None,
                    max_passes=2,
                )
            else:
                new = cand[rng.choice(free, n_new, replace=False)]
            taken = [free[int(np.flatnonzero(np.all(cand[free] == row, axis=1))[0])] for row in new]
            unused[taken] = False
        q = np.vstack([q, new])
        got = measure(new)
        if not isinstance(got, Measurements) or got.n_poses != len(new):
            raise CalibrationError(
                "measure(q) must return a Measurements with one row per requested pose"
            )
        if got.session is not None:
            raise CalibrationError(
                "calibrate_until does not take measurements of several sessions yet (a "
                "session column): its batches would split the sessions into a few poses "
                "each; measure one session, or fit the sessions with identify"
            )
        meas = got if meas is None else meas.concat(got)
        try:
            cal = identify(robot, meas, parameters, method)
            pred = predicted_error(cal, q_hold) if cal.success else np.inf
        except CalibrationError as exc:
            if "fewer than" not in str(exc):
                raise
            pred = np.inf  # too few poses yet
        history.append((len(q), pred))
        if pred < threshold or len(q) >= max_poses:
            break
        n = len(q) + batch
    if cal is None:
        raise CalibrationError(f"{len(q)} poses could not be identified at all")
    return Campaign(cal, meas, pred, tuple(history), bool(pred < threshold), threshold)


def pool_measure(pool: Measurements) -> tuple[np.ndarray, Callable]:
    """Candidates and a `measure` that looks requested poses up in measured `pool`."""

    def measure(q):
        rows = []
        for row in q:
            # equal up to the round trip of a pose through the file's degrees
            hit = np.flatnonzero(np.all(np.abs(pool.q - row) <= 1e-9, axis=1))
            if not len(hit):
                raise CalibrationError(
                    "a requested pose is not in the measured pool: order 'seed' (--order "
                    "seed) takes the paper's schedule, so the pool must hold it (measure it, "
                    "or simulate with --schedule seed); else use --order optimal or uniform"
                )
            rows.append(int(hit[0]))
        return pool.take(rows)

    return pool.q.copy(), measure
