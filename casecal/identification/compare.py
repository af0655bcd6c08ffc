"""Which error model do the data support? Nested models fitted to the same poses, side by
side: parameters, in-sample RMS, k-fold cross-validated RMS and information criteria."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ..errors import CalibrationError
from .fit import identify


@dataclass(frozen=True)
class ModelComparison:
    """The table of `compare_models` and the model it picks.

    Attributes
    ----------
    table : DataFrame
        One row per model: ``model``, ``parameters`` (estimated), ``rms_mm`` (in-sample,
        per point), ``cv_rms_mm`` and ``cv_se_mm`` (k-fold cross-validated, per point,
        with its standard error over the folds), ``aic``, ``bic``, ``success`` (of the fit
        on all poses) and ``message``.
    best : str
        Among the models whose fit on all poses passed its answer audit, the one with the
        fewest parameters whose cross-validated RMS is within one standard error of the
        lowest (the one-standard-error rule): more parameters must predict measurably
        better to be chosen. Empty when no fit passed.
    """

    table: pd.DataFrame
    best: str

    def __str__(self) -> str:
        shown = self.table.drop(columns="message").to_string(index=False, float_format="%.4g")
        if not self.best:
            return f"{shown}\nno model's fit passed its answer audit: none is chosen"
        return f"{shown}\nchosen by cross-validation: {self.best}"


def _points(cal, meas) -> np.ndarray:
    """`cal`'s robot's measured points at `meas`' poses, (N, 3m): each pose through its
    session's frames where `cal` fitted several."""
    if not cal.sessions or meas.session is None:
        return cal.robot.measured_points(meas.q).reshape(meas.n_poses, -1)
    out = np.empty((meas.n_poses, meas.positions[0].size))
    for label in meas.sessions:
        rows = meas.session == label
        out[rows] = cal.session_robot(label).measured_points(meas.q[rows]).reshape(rows.sum(), -1)
    return out


def _nominal(model, measurements):
    """The robot of `model`: itself, or built from `measurements` when it is a builder."""
    from ..model.robot import Robot

    if isinstance(model, Robot):
        return model
    if not callable(model):
        raise CalibrationError(
            f"compare_models takes robots or functions of the measurements that return "
            f"one, not {type(model).__name__}"
        )
    return model(measurements)


def _criteria(cal, meas, n_estimated: int) -> tuple[float, float]:
    """AIC and BIC of a fit: from χ² with a stated σ, else from the residual sum of squares."""
    r = cal.residuals.reshape(meas.n_poses, -1)
    n = r.size
    if cal.sigma_known:
        sigma = np.repeat(meas.sigma, r.shape[1] // 3, axis=0).reshape(r.shape)
        fit = float(np.sum((r / sigma) ** 2))
    else:
        fit = n * float(np.log(max(np.sum(r**2) / n, 1e-300)))
    return fit + 2 * n_estimated, fit + n_estimated * float(np.log(n))


def compare_models(
    models: Mapping[str, object],
    measurements,
    parameters="all",
    method=None,
    folds: int = 5,
    seed: int = 0,
) -> ModelComparison:
    """Fit each robot model of `models` (name → nominal `Robot`) to `measurements`.

    Parameters
    ----------
    models : mapping of str to Robot or callable
        Usually nested: the rigid robot, then with compliance, then with harmonics. A
        callable ``model(measurements) -> Robot`` builds its robot from the poses it is
        fitted to, once on all of them and again on each fold's training poses, so that
        a choice it makes from the data (`casecal.identification.lumped_select.
        ReducedLumped`: the lumped gravity terms that predict) is cross-validated too.
    measurements : Measurements
    parameters : str or list
        As for `identify`, for every model ("all": each model's own full set).
    method : str, optional
        As for `identify` (default its default).
    folds : int
        k of the k-fold cross-validation (poses split at random, `seed`).

    Returns
    -------
    ModelComparison
    """
    if getattr(measurements, "contact", None):
        raise CalibrationError(
            "comparing models on contact sessions (fixed points, planes) is not supported "
            "yet: their held-out errors are not positions; compare on measured points"
        )
    if not models:
        raise CalibrationError("compare_models needs at least one model")
    n = measurements.n_poses
    if not 2 <= folds <= n:
        raise CalibrationError(f"folds must be between 2 and the number of poses ({n})")
    fold = np.random.default_rng(seed).permutation(n) % folds
    kwargs = {} if method is None else {"method": method}
    rows = []
    for name, model in models.items():
        cal = identify(_nominal(model, measurements), measurements, parameters, **kwargs)
        errors = []
        for k in range(folds):
            train, test = measurements.take(fold != k), measurements.take(fold == k)
            try:
                part = identify(_nominal(model, train), train, parameters, **kwargs)
            except CalibrationError as exc:
                raise CalibrationError(
                    f"model {name!r}, cross-validation fold {k + 1} of {folds} "
                    f"({train.n_poses} of {n} poses): {exc}; use fewer folds or more poses"
                ) from None
            miss = _points(part, test) - test.positions.reshape(test.n_poses, -1)
            errors.append(np.mean(np.sum(miss.reshape(-1, 3) ** 2, axis=1)))
        per_fold = np.sqrt(errors)
        aic, bic = _criteria(cal, measurements, len(cal.estimated))
        rows.append(
            {
                "model": name,
                "parameters": len(cal.estimated),
                "rms_mm": cal.rms * 1e3,
                "cv_rms_mm": float(np.sqrt(np.mean(errors))) * 1e3,
                "cv_se_mm": float(np.std(per_fold, ddof=1) / np.sqrt(folds)) * 1e3,
                "aic": aic,
                "bic": bic,
                "success": cal.success,
                "message": cal.message,
            }
        )
    table = pd.DataFrame(rows)
    passed = table[table.success]
    if passed.empty:
        return ModelComparison(table, "")  # no fit passed its audit: none is chosen
    lowest = passed.cv_rms_mm.idxmin()
    near = passed[passed.cv_rms_mm <= passed.cv_rms_mm[lowest] + passed.cv_se_mm[lowest]]
    best = str(near.sort_values(["parameters", "cv_rms_mm"]).model.iloc[0])
    return ModelComparison(table, best)
