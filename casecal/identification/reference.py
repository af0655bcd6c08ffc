"""What "before calibration" means: the nominal robot with the unknown frames fitted.

The frames (the base, where the instrument stands; the tool and the reflectors, where the
probe sits) are not errors of the robot: nobody could have known them before measuring.
The error the robot had before calibration is what remains when they are fitted to the
data and the robot's own parameters keep their nominal values. Judged against the nominal
robot with its nominal frames instead, a tracker metres away or reflectors with unknown
offsets make "before" hundreds of millimetres, and every check that asks whether the fit
helped (the prediction check, what a parameter's uncertainty may not exceed, model
comparison) passes because of the frames alone.
"""

from __future__ import annotations

import dataclasses

from ..model.robot import Robot
from .rounds import Settings, fit_in_rounds

FRAME_PREFIXES = ("base_", "tool_", "point")


def frame_parameters(names, robot: Robot | None = None) -> list[str]:
    """The asked-for parameters that locate frames rather than the robot's geometry: with
    `robot` a tree, its tips' frames too (where the markers sit)."""
    tips = tuple(f"{t}." for t in robot.tips) if robot is not None and robot.is_tree else ()
    return [n for n in names if n.startswith(FRAME_PREFIXES) or (tips and n.startswith(tips))]


def frames_fitted(make, start: Robot, names, settings: Settings, e0: float) -> Robot:
    """`start` with the asked-for frame parameters fitted to the data, the rest held.

    Parameters
    ----------
    make : callable(robot, names=...) -> Problem
        The measurements, fit frame.
    start : Robot
        Where the fit starts: the nominal robot (its base possibly from a rigid fit).
    names : sequence of str
        The asked-for parameters.
    settings : Settings
        The fit's; the reference is a plain least-squares Gauss-Newton fit whatever the
        fit's own method, loss, bounds or prior.
    e0 : float
        RMS error at `start`, m.

    Returns
    -------
    Robot
        `start` itself when no frame, or nothing but frames, is asked for (the
        calibration is then the frame fit: before it is the start), or when the frame fit
        fails.
    """
    frames = frame_parameters(names, start)
    if not frames or len(frames) == len(names):
        return start
    plain = dataclasses.replace(
        settings, method="gauss-newton", loss="linear", bounds={}, prior={}, progress=None
    )
    out = fit_in_rounds(make, start, frames, plain, e0)
    if out.solver_status < 0:
        return start
    return out.robot


FALLBACK_NOTE = (
    "The frames alone could not be fitted to these data, so 'before' is the nominal robot "
    "with its nominal frames (the instrument's placement counts in it)."
)
"""What the summary says when `frames_fitted` fell back to the start."""
