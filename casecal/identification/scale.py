"""Units at the door of `casecal.identify`, and the check that a fit kept the robot's size.

Before the fit, `door` runs the checks of `casecal.data.units` on `Measurements` (SI).
After it, `with_size_check` adds the audit check **robot keeps its size**: the calibrated
robot's measured points over poses across the joint ranges are compared, by a similarity
fit, with the nominal robot's. With ``parameters="all"`` every length of a DH arm is free,
so a point cloud measured 1000 times too small is fitted exactly by a robot 1000 times
smaller (a PUMA 560 with a2 = 0.43 mm): the residuals, the noise, the prediction all pass.
No calibration changes a real robot's size by half or double; a unit does.
"""

from __future__ import annotations

import math

import numpy as np

from ..data.measurements import Measurements
from ..data.units import (
    SHAPE,
    api_unit_words,
    at_the_door,
    length_unit_slip,
    ratio_text,
    similarity,
)
from ..design.poses import uniform
from ..model.robot import Robot
from .audit import Audit, Check

SIZE_LIMIT = 2.0
"""A calibrated robot more than this many times larger or smaller than the nominal one
(over poses across its joint ranges) is a unit slip or a wrong robot file, not a
calibration."""

SIZE_POSES = 200

NAME = "robot keeps its size"


def door(robot: Robot, measurements: Measurements) -> None:
    """Refuse or warn about unit slips in `measurements` (`casecal.data.units.at_the_door`),
    on the poses whose every coordinate was measured (σ not inf)."""
    rows = np.all(measurements.measured, axis=1)
    if not np.all(rows):
        if np.count_nonzero(rows) < 3:  # too few whole points to see a unit by
            return
        measurements = measurements.take(rows)
    at_the_door(robot, measurements.q, measurements.points)


def size_of(nominal: Robot, fitted: Robot, q: np.ndarray):
    """The similarity (`casecal.data.units.similarity`) of `fitted`'s measured points to
    `nominal`'s over poses across the joint ranges (the measured poses `q` without
    limits): its ``scale`` is how much larger the fitted robot is."""
    try:
        poses = uniform(nominal, SIZE_POSES, seed=0)
        if nominal.inputs:
            poses = np.column_stack([poses, np.tile(q[0, nominal.dof :], (len(poses), 1))])
        a, b = nominal.measured_points(poses), fitted.measured_points(poses)
    except (ValueError, TypeError):  # no limits to draw from: the measured poses
        a, b = nominal.measured_points(q), fitted.measured_points(q)
    return similarity(a.reshape(-1, 3), b.reshape(-1, 3)), a, b


def board_size_check(nominal: Robot, fitted: Robot, q: np.ndarray, spacing: float) -> Check:
    """**robot keeps its size** for a camera calibration, whose only length is the board's
    spacing: a fitted robot off by more than `SIZE_LIMIT` is a spacing in another unit."""
    size = size_of(nominal, fitted, q)[0]
    if not size.spread_nominal > 1e-6 or not math.isfinite(size.scale):
        return Check(NAME, None, "the nominal robot's measured points do not move")
    text = f"the calibrated robot is {size.scale:.4g}× the nominal's size over its joint ranges"
    if _within(size.scale):
        return Check(NAME, True, text)
    return Check(
        NAME,
        False,
        f"{text}: the board's spacing ({spacing * 1e3:g} mm a square) sets the scale of every "
        f"length, and it is likely {ratio_text(size.scale)} the board's: check its unit "
        "(board_spacing_mm in a camera file; Checkerboard.spacing in m). Do not use this robot",
    )


def size_check(nominal: Robot, fitted: Robot, q: np.ndarray, y: np.ndarray) -> Check:
    """The check of the module doc.

    Parameters
    ----------
    nominal, fitted : Robot
        The same structure (the fitted one in any base frame).
    q : ndarray, shape (N, dof)
        The measured poses, SI (for the message and when the robot has no joint limits).
    y : ndarray, shape (N, m, 3)
        The measured points, m.
    """
    size, a, b = size_of(nominal, fitted, q)
    if not size.spread_nominal > 1e-6 or not math.isfinite(size.scale):
        return Check(NAME, None, "the nominal robot's measured points do not move")
    ratio, what, k = size.scale, "the calibrated robot is", slice(None)
    if nominal.is_tree and _within(ratio):
        # a tree's branch shrunk onto one tip's points in another unit: the others hide it
        for j, tip in enumerate(nominal.tips):
            one = similarity(a[:, j], b[:, j])
            if one.spread_nominal > 1e-6 and not _within(one.scale):
                ratio, what, k = one.scale, f"tip {tip!r} of the calibrated robot is", [j]
                break
    text = f"{what} {ratio:.4g}× the nominal's size over its joint ranges"
    if _within(ratio):
        return Check(NAME, True, text)
    seen = similarity(nominal.measured_points(q)[:, k].reshape(-1, 3), y[:, k].reshape(-1, 3))
    if unit_slip(seen, ratio):
        return Check(
            NAME,
            False,
            f"{text}: the fit rescaled the robot to match measured points that span "
            f"{ratio_text(seen.scale)} what the nominal robot reaches at these joint values: "
            f"{_slip(seen.scale)}",
        )
    return Check(
        NAME,
        False,
        f"{text}, while the measured points are not a scaled copy of the nominal robot's: "
        "parameters these poses barely see moved far (no calibration changes a robot's size "
        "so); measure poses that move every joint",
    )


def _within(ratio: float) -> bool:
    return 1 / SIZE_LIMIT <= ratio <= SIZE_LIMIT


def unit_slip(seen, ratio: float) -> bool:
    """Whether the measured points are a copy of the nominal ones scaled like the fit."""
    return (
        math.isfinite(seen.scale)
        and seen.scale > 0
        and seen.shape_error <= 2 * SHAPE
        and abs(math.log(seen.scale)) > math.log(SIZE_LIMIT)
        and math.log(seen.scale) * math.log(ratio) > 0
    )


def _slip(ratio: float) -> str:
    """The likely unit slip behind a measured-over-nominal size `ratio`."""
    in_mm = length_unit_slip(ratio, "mm")
    in_m = length_unit_slip(ratio, "m")
    words = {"m": "metres", "mm": "millimetres", "um": "micrometres", "in": "inches"}
    words.update(cm="centimetres", km="kilometres")
    if in_mm in words and in_mm != "km":
        csv = f"are x_mm, y_mm, z_mm in {words[in_mm]}?"
    else:
        csv = "check the unit of the CSV's x_mm, y_mm, z_mm (or x, y, z in m) columns"
    api = f"positions {api_unit_words(in_m)}" if in_m in words else "positions not in metres"
    return (
        f"{csv} (in Measurements built in code: {api}? they take metres); or the robot "
        "file's length_unit is wrong. Do not use this robot"
    )


def with_size_check(checks: Audit, nominal: Robot, fitted: Robot, q, y) -> Audit:
    """`checks` with `size_check`: first when it names a unit slip (the cause of every
    other failure then), last otherwise (poses that cannot support the parameters are the
    cause, named by the prediction check)."""
    size = size_check(nominal, fitted, q, y)
    if size.passed is False and "fit rescaled the robot" in size.text:
        return Audit((size, *checks.checks))
    return Audit((*checks.checks, size))
