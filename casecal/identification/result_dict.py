"""A `Calibration` as plain data: one JSON-ready dict (`calibration_dict`) and one row per
measured point (`residual_rows`), for scripts, pipelines and ``--json``.

Units are in the key names (``rms_after_mm``, ``wall_time_s``); a parameter's values are in
its ``unit`` (mm, deg, or the unit its family is shown in), as `Calibration.table` shows
them, and again in SI under ``deviations_si``. NaN and infinity become None, so the dict
is valid JSON (``json.dumps(..., allow_nan=False)``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

    from .calibration import Calibration

SCHEMA = "casecal.calibration/1"
"""Names the layout of `calibration_dict`; a change of its keys changes the number."""

PARAMETER_KEYS = (
    "parameter", "unit", "nominal", "deviation", "std_error", "ci95_low", "ci95_high", "status",
)  # fmt: skip


def _number(value) -> float | int | None:
    """A JSON-safe number: None for NaN and ±inf."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def calibration_dict(cal: Calibration) -> dict:
    """Everything a script needs from `cal`, JSON-ready (module doc; keys in the README).

    Parameters
    ----------
    cal : Calibration

    Returns
    -------
    dict
        ``schema``, ``method``, ``success``, ``status``, ``message``, ``solver_status``,
        ``iterations``, ``rounds``, ``n_poses``, ``measured``, ``sigma_known``,
        ``rms_before_mm``, ``rms_after_mm``, ``max_error_before_mm``,
        ``max_error_after_mm``, ``reduced_chi2``, ``dof_residual``, ``wall_time_s``,
        ``parameters`` (one dict per asked-for parameter: `PARAMETER_KEYS`, values in
        ``unit``; ``synthetic`` and ``error_pct`` too when the truth is known),
        ``deviations_si`` (name to SI value), ``estimated``, ``held``, ``unidentifiable``,
        ``poorly_determined``, ``joined``, ``blind_spots`` (sentences), ``outliers``
        (0-based poses), ``audit`` (``passed`` and ``checks``: name, passed, text).
    """
    table = cal.table
    parameters = []
    for row in table.to_dict(orient="records"):
        entry = {k: (row[k] if k in ("parameter", "unit", "status") else _number(row[k]))
                 for k in PARAMETER_KEYS}  # fmt: skip
        for extra in ("synthetic", "error_pct"):
            if extra in row:
                entry[extra] = _number(row[extra])
        parameters.append(entry)
    audit = cal.audit
    return {
        "schema": SCHEMA,
        "method": cal.method,
        "success": bool(cal.success),
        "status": int(cal.status),
        "message": cal.message,
        "solver_status": None if cal.solver_status is None else int(cal.solver_status),
        "iterations": int(cal.iterations),
        "rounds": int(cal.rounds),
        "n_poses": int(cal.n_poses),
        "measured": cal.measured,
        "sigma_known": bool(cal.sigma_known),
        "rms_before_mm": _number(cal.rms_before * 1e3),
        "rms_after_mm": _number(cal.rms * 1e3),
        "max_error_before_mm": _number(cal.max_error_before * 1e3),
        "max_error_after_mm": _number(cal.max_error * 1e3),
        "reduced_chi2": _number(cal.reduced_chi2),
        "dof_residual": int(cal.dof_residual),
        "wall_time_s": _number(cal.wall_time),
        "parameters": parameters,
        "deviations_si": {n: _number(v) for n, v in cal.deviations.items()},
        "estimated": list(cal.estimated),
        "held": list(cal.held),
        "unidentifiable": list(cal.unidentifiable),
        "poorly_determined": list(cal.poorly_determined),
        "joined": list(cal.joined),
        "blind_spots": [spot.text for spot in cal.observability.blind_spots],
        "outliers": [int(i) for i in cal.outliers],
        "audit": {
            "passed": None if audit is None else bool(audit.passed),
            "checks": []
            if audit is None
            else [{"name": c.name, "passed": c.passed, "text": c.text} for c in audit.checks],
        },
    }


def residual_rows(cal: Calibration) -> pd.DataFrame:
    """One row per measured point: its pose, the error before and after, mm.

    Columns: ``pose`` (0-based), ``point`` (0-based, of the pose's measured points),
    ``dx_before_mm``, ``dy_before_mm``, ``dz_before_mm``, ``error_before_mm`` (length),
    the same ``..._after_mm``, and ``outlier`` (the pose is among `Calibration.outliers`).
    Residuals are measured minus modelled (`Calibration.residuals`); for distances and a
    camera's pixels they are what `Calibration.measured` says, in mm at the target.
    """
    import pandas as pd

    before, after = cal.residuals_before, cal.residuals
    rows = after.shape[0]
    if cal.measured != "points" or after.shape[1:] != (3,) or rows % max(cal.n_poses, 1):
        from ..errors import CalibrationError

        # pairs of poses (distances) or a camera's corners: rows that name no single pose
        raise CalibrationError(
            f"the residual table is of measured points, one or more per pose; this "
            f"calibration measured {cal.measured}: see its summary and `residuals`"
        )
    per_pose = rows // cal.n_poses
    index = np.arange(rows)
    pose, point = index // per_pose, index % per_pose
    data = {"pose": pose, "point": point}
    for label, r in (("before", before), ("after", after)):
        for axis, column in zip("xyz", r.T * 1e3, strict=True):
            data[f"d{axis}_{label}_mm"] = column
        data[f"error_{label}_mm"] = np.linalg.norm(r, axis=1) * 1e3
    data["outlier"] = np.isin(pose, np.asarray(cal.outliers, dtype=int))
    return pd.DataFrame(data)


def _stats(stats, scale: float, unit: str) -> dict | None:
    """`ErrorStats` as ``rms_<unit>``, ``mean_<unit>``, ``max_<unit>``, ``n_points``."""
    if stats is None:
        return None
    return {
        f"rms_{unit}": _number(stats.rms * scale),
        f"mean_{unit}": _number(stats.mean * scale),
        f"max_{unit}": _number(stats.max * scale),
        "n_points": int(stats.n_points),
    }


def validation_dict(validation) -> dict:
    """A `casecal.validate` result, JSON-ready: ``schema``, ``n_poses``, ``before`` and
    ``after`` (``rms_mm``, ``mean_mm``, ``max_mm``, ``n_points``), and where orientations
    were measured ``rotation_before`` and ``rotation_after`` (the same in mrad, else None)."""
    return {
        "schema": "casecal.validation/1",
        "n_poses": int(validation.n_poses),
        "before": _stats(validation.before, 1e3, "mm"),
        "after": _stats(validation.after, 1e3, "mm"),
        "rotation_before": _stats(validation.rotation_before, 1e3, "mrad"),
        "rotation_after": _stats(validation.rotation_after, 1e3, "mrad"),
    }


def observability_dict(obs) -> dict:
    """A `casecal.observability` result, JSON-ready: ``schema``, ``n_poses``,
    ``parameters``, ``rank``, ``identifiable``, ``unidentifiable``, ``base_parameters``,
    ``blind_spots`` (sentences), ``singular_values`` (of the column-scaled Jacobian, no
    unit) and ``indices`` (O1 … O5)."""
    return {
        "schema": "casecal.observability/1",
        "n_poses": int(obs.n_poses),
        "parameters": list(obs.parameters),
        "rank": int(obs.rank),
        "identifiable": list(obs.identifiable),
        "unidentifiable": list(obs.unidentifiable),
        "base_parameters": list(obs.base_parameters),
        "blind_spots": [spot.text for spot in obs.blind_spots],
        "singular_values": [_number(s) for s in obs.singular_values],
        "indices": {k: _number(v) for k, v in obs.indices.items()},
    }


def comparison_dict(comparison) -> dict:
    """A `casecal.compare_models` result, JSON-ready: ``schema``, ``best`` (the chosen
    model, "" when no fit passed) and ``models``: one dict per model with ``model``,
    ``parameters``, ``rms_mm``, ``cv_rms_mm``, ``cv_se_mm``, ``aic``, ``bic``,
    ``success`` and ``message``."""
    models = []
    for row in comparison.table.to_dict(orient="records"):
        models.append(
            {
                k: (_number(v) if isinstance(v, float) else v.item() if hasattr(v, "item") else v)
                for k, v in row.items()
            }
        )
    return {"schema": "casecal.comparison/1", "best": comparison.best, "models": models}
