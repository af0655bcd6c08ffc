"""Lumped gravity terms the data determine: a forward-stepwise path whose length is chosen
by cross-validated prediction error with the one-standard-error rule.

Without masses, a joint's bending under gravity is linear in lumped terms (mass × centre
of mass × compliance, `casecal.model.terms.lumped_compliance`); after their exact
redundancy (`casecal.model.lumped_basis`) a 6R arm still has 28. Most describe bodies
whose weight bends the arm by less than the noise: fitted, they adapt to the noise of the
poses measured and predict other poses worse than leaving them out (on a Stäubli TX2-90L,
six terms predicted better than 36). Which terms predict is decided on poses the fit did
not see:

1. The robot without lumped terms is fitted (`identify`), and the fit is linearised there:
   residuals ``r`` and the Jacobian columns of its estimated parameters and of every
   candidate lumped term. The model is linear in the lumped terms, and the deviations
   change the columns only at second order (a 1e-3 rad deviation moves a column by 1e-3
   of itself, micrometres against a noise of tens), so the linear fit predicts as the
   nonlinear one does.
2. Forward stepwise (Hastie, Tibshirani & Friedman 2009, *The Elements of Statistical
   Learning*, §3.3.2): starting from no lumped term, each step adds the candidate that
   lowers the weighted residual sum of squares of the fit to every pose most, the
   geometric parameters fitted along, down to the last candidate: a path of nested models.
3. Its length by k-fold cross-validation with the one-standard-error rule (Breiman et
   al. 1984, *Classification and Regression Trees*, §3.4; Hastie et al. §7.10): the
   shortest model on the path whose cross-validated RMS is within one standard error
   (over the folds, as `compare_models` computes it) of the lowest. The lowest is itself
   a noisy estimate; terms beyond the shortest model within its noise are not shown to
   predict.

The path is ordered by the fit, not by the cross-validated error: choosing each step's
term among twenty on the same folds makes the error along the path optimistic, and it then
keeps terms that do not predict (on an RX90-class arm at 40 poses, six trials: up to two
terms more, a held-out error never lower and up to 3 % higher).

The cross-validated error at the chosen length is optimistic (the length was chosen on the
same folds): to measure the chosen set's prediction error honestly, repeat the selection inside each
training fold, which `compare_models` does for a `ReducedLumped` model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..errors import CalibrationError
from ..model import kinematics
from ..model.lumped_basis import REDUNDANT, lumped_subset, reduced_lumped_terms
from ..model.robot import Robot
from .fit import identify

LUMPED_KINDS = ("lumped_compliance", "lumped_compliance_subset", "compliance")


@dataclass(frozen=True)
class LumpedSelection:
    """What `select_lumped` chose and why.

    Attributes
    ----------
    robot : Robot
        The nominal robot with the chosen lumped terms (values zero), for `identify`.
    names : tuple of str
        The chosen lumped terms, in the order they entered.
    candidates : tuple of str
        Every lumped term without exact redundancy (`reduced_lumped_terms`).
    path : DataFrame
        One row per step of the forward selection: ``terms`` (lumped terms in the model),
        ``added`` (the term that entered, "" at step 0), ``chi2`` (the weighted residual
        sum of squares of the linearised fit to every pose; in units of σ² when the
        measurements state σ), ``cv_rms_mm`` and ``cv_se_mm``
        (k-fold cross-validated RMS per point of the linearised fit, mm, and its standard
        error over the folds), ``chosen`` (True on the row the rule picked).
    """

    robot: Robot
    names: tuple[str, ...]
    candidates: tuple[str, ...]
    path: pd.DataFrame


def select_lumped(
    robot: Robot,
    measurements,
    joints=None,
    parameters="all",
    folds: int = 5,
    seed: int = 0,
    method=None,
) -> LumpedSelection:
    """The lumped gravity terms of `robot` that predict `measurements` (module doc).

    Parameters
    ----------
    robot : Robot
        The nominal robot, without compliance terms (other terms are fitted along).
    measurements : Measurements
        Measured points (m) of one session; orientations, if any, are not used here.
    joints : sequence of int, optional
        Candidate joints (1-based); None: those that carry gravity load.
    parameters : str or list
        What `identify` estimates besides the lumped terms (default every parameter).
    folds : int
        k of the cross-validation; the poses are split at random (`seed`) as
        `compare_models` splits them.
    method : str, optional
        `identify`'s method for the fit without lumped terms.

    Returns
    -------
    LumpedSelection
    """
    _check(robot, measurements, folds)
    candidates = reduced_lumped_terms(robot, joints)
    if not candidates:
        raise CalibrationError(
            f"robot {robot.name!r}: no joint carries gravity load (its axes are vertical "
            "or nothing beyond them has a lever): there are no lumped terms to choose"
        )
    names = [n for t in candidates for n in t.parameters]
    kwargs = {} if method is None else {"method": method}
    cal = identify(robot, measurements, parameters, **kwargs)
    r, G, L, w = _linearised(cal.robot.with_terms(*candidates), measurements, cal.estimated, names)
    fold = np.random.default_rng(seed).permutation(measurements.n_poses) % folds
    path = _path(r, G, L, w, fold, folds)
    path["added"] = ["" if k < 0 else names[k] for k in path.pop("column")]
    best = path.cv_rms_mm.idxmin()
    limit = path.cv_rms_mm[best] + path.cv_se_mm[best]
    chosen = int(path.index[path.cv_rms_mm <= limit][0])
    path["chosen"] = path.index == chosen
    kept = tuple(path.added[1 : chosen + 1])
    n = len(robot.uncoupled().joints)
    terms = [
        lumped_subset(t.joint, n, [x for x in t.parameters if x in kept])
        for t in candidates
        if set(t.parameters) & set(kept)
    ]
    return LumpedSelection(robot.with_terms(*terms), kept, tuple(names), path)


def _check(robot, measurements, folds: int) -> None:
    if any(t.kind in LUMPED_KINDS for t in robot.terms):
        raise CalibrationError(
            f"robot {robot.name!r} already has compliance terms; give the robot without "
            "them, and the lumped terms are chosen from all of its joints"
        )
    if getattr(measurements, "positions", None) is None or not hasattr(measurements, "session"):
        raise CalibrationError(
            "choosing lumped terms needs measured positions (Measurements), not distances or pixels"
        )
    if measurements.session is not None or getattr(measurements, "contact", None):
        raise CalibrationError(
            "choosing lumped terms needs measured points of one session; select on one "
            "session's measurements (Measurements.take)"
        )
    n = measurements.n_poses
    if not 2 <= folds <= n:
        raise CalibrationError(f"folds must be between 2 and the number of poses ({n})")


def _linearised(robot: Robot, meas, geometric, lumped) -> tuple:
    """Residuals (N, 3m) and the columns of `geometric` (N, 3m, g) and of `lumped`
    (N, 3m, l) at `robot`, m per unit parameter, and the weights 1/σ (N, 3m)."""
    q = robot.model_joints(meas.q)
    q = q.reshape(meas.n_poses, -1)
    chain = kinematics.chain(robot.structure)
    p = robot.vector()
    y = meas.positions.reshape(meas.n_poses, -1)
    r = y - chain.evaluate("points", q, p).reshape(y.shape)
    G = chain.evaluate("points_jacobian", q, p, chain.columns(geometric), anchor=p)
    L = chain.evaluate("points_jacobian", q, p, chain.columns(lumped), anchor=p)
    sigma = np.tile(meas.sigma, y.shape[1] // 3)
    if not np.all(np.isfinite(sigma) & (sigma > 0)):  # no σ stated: equal weights
        return r, G, L, np.ones_like(sigma)
    return r, G, L, 1.0 / sigma


def _path(r, G, L, w, fold, folds: int) -> pd.DataFrame:
    """The forward-stepwise path (module doc): per step the column added (-1 at step 0),
    the weighted residual sum of squares of the fit to every pose, and the k-fold
    cross-validated RMS (mm per point) with its standard error over the folds."""
    # unit columns: metres and radians must not decide lstsq's rank cut-off
    G = G / np.maximum(np.linalg.norm(G, axis=(0, 1)), 1e-300)
    L = L / np.maximum(np.linalg.norm(L, axis=(0, 1)), 1e-300)
    splits = [(fold != k, fold == k) for k in range(folds)]
    rows = min(np.sum(train) for train, _ in splits) * r.shape[1]
    chosen, fits = _stepwise((r * w).reshape(-1), _rows(G, w), _rows(L, w), rows - G.shape[2])
    errors = np.array(
        [_fit(r, np.concatenate([G, L[:, :, chosen[:t]]], 2), w, splits) for t in range(len(fits))]
    )
    per_fold = np.sqrt([[e[fold == k].mean() for k in range(folds)] for e in errors])
    return pd.DataFrame(
        {
            "terms": np.arange(len(fits)),
            "column": [-1, *chosen],
            "chi2": fits,
            "cv_rms_mm": np.sqrt(errors.mean(axis=1)) * 1e3,
            "cv_se_mm": per_fold.std(axis=1, ddof=1) / np.sqrt(folds) * 1e3,
        }
    )


def _rows(X, w) -> np.ndarray:
    """(N, 3m, k) columns weighted by `w` (N, 3m), as a (N·3m, k) matrix."""
    return (X * w[:, :, None]).reshape(-1, X.shape[2])


def _stepwise(b, A, C, most: int) -> tuple[list[int], list[float]]:
    """Forward stepwise on ``b ≈ A α + C[:, S] β``: the columns of C in the order they
    enter (each lowering the residual sum of squares most) and the sum after each step
    (the first before any). Orthogonal updates: each step projects the column taken out
    of the residual and of the columns left."""
    u, s, _ = np.linalg.svd(A, full_matrices=False)
    Q = u[:, s > REDUNDANT * s[0]] if s.size else u[:, :0]
    res = b - Q @ (Q.T @ b)
    C = C - Q @ (Q.T @ C)
    size = np.linalg.norm(C, axis=0)  # a column left with less than this share is spanned
    chosen, fits = [], [float(res @ res)]
    while len(chosen) < min(C.shape[1], most):
        norm2 = np.sum(C**2, axis=0)
        alive = norm2 > (REDUNDANT * size) ** 2
        alive[chosen] = False
        if not alive.any():
            break
        gain = np.where(alive, (C.T @ res) ** 2 / np.where(alive, norm2, 1.0), -1.0)
        k = int(np.argmax(gain))
        q = C[:, k] / np.sqrt(norm2[k])
        res = res - q * (q @ res)
        C = C - np.outer(q, q @ C)
        chosen.append(k)
        fits.append(float(res @ res))
    return chosen, fits


def _fit(r, X, w, splits) -> np.ndarray:
    """Per pose, the squared error (m², mean over its points) with which the weighted
    linear fit ``r ≈ X β`` on the other folds predicts it."""
    out = np.zeros(r.shape[0])
    for train, test in splits:
        beta = np.linalg.lstsq(_rows(X[train], w[train]), (r[train] * w[train]).ravel())[0]
        miss = (r[test] - X[test] @ beta).reshape(-1, r.shape[1] // 3, 3)
        out[test] = np.mean(np.sum(miss**2, axis=2), axis=1)
    return out


@dataclass(frozen=True)
class ReducedLumped:
    """A model for `compare_models` whose lumped terms are chosen from the poses it is
    fitted to (`select_lumped`), so that each cross-validation fold chooses again on its
    own training poses and the held-out error includes the choice.

    Attributes
    ----------
    robot : Robot
        The nominal robot without compliance terms.
    joints, folds, seed
        As for `select_lumped`.
    """

    robot: Robot
    joints: tuple | None = None
    folds: int = 5
    seed: int = 0

    def __call__(self, measurements) -> Robot:
        """The nominal robot with the lumped terms chosen on `measurements`."""
        joints = None if self.joints is None else list(self.joints)
        folds = min(self.folds, measurements.n_poses)  # a small fold of compare_models'
        return select_lumped(self.robot, measurements, joints, folds=folds, seed=self.seed).robot
