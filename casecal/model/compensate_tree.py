"""Compensation on a kinematic tree (several tips, `casecal.model.tree`): one joint search
per pose for every tip at once.

A tree's tips share joints (a torso carries both arms), so a pose's joints cannot be
corrected tip by tip: `casecal.model.compensate` solves, per pose, one least-squares
problem over all the model's joints, whose rows are every tip's pose error against where
the nominal tree puts that tip (`casecal.model.compensate_solve`, rows stacked tip after
tip, six per tip: position m, then rotation vector rad).

Which rows a tip contributes follows the serial rule, per tip: its orientation as well as
its position when six or more controller joints move it (the joints on its path from the
base, counted through the coupling), its position only with fewer (`tree_rows`). With
more joints than matched rows (a humanoid's two hands: 12 rows, 17 joints), the search
takes the smallest correction from the commanded joints (the minimum-norm Gauss-Newton
step, joints weighed by their levers). With more rows than joints (a torso of three joints
and two arms of three: six joints move each hand, 12 rows for 9 joints), no joint values
put every tip there in general, and that is refused (`tree_rows`). A pose the calibrated
tree cannot put every tip on is reported out of reach with what it misses, never returned
as corrected.
"""

from __future__ import annotations

import numpy as np

from ..errors import CalibrationError
from .robot import Robot


def check_same_tips(nominal: Robot, calibrated: Robot) -> None:
    """Raise CalibrationError unless both robots are trees of the same tips, or neither is
    (a serial chain's tip may be named differently: a URDF's link, a robot file's "tool")."""
    if not (nominal.is_tree or calibrated.is_tree):
        return
    if nominal.is_tree != calibrated.is_tree or nominal.tips != calibrated.tips:
        words = {True: "a tree with tips", False: "a chain to"}
        raise CalibrationError(
            f"the nominal robot is {words[nominal.is_tree]} {', '.join(nominal.tips)}, the "
            f"calibrated one {words[calibrated.is_tree]} {', '.join(calibrated.tips)}: "
            "compensation needs the same tips on both; load the nominal robot with the "
            "calibrated one's tips (tip_link=, --tip-link)"
        )


def tip_joints(robot: Robot) -> list[int]:
    """Per tip of tree `robot`, how many controller joints move it: those that drive a model
    joint on its path from the base (`Robot.parents`), through the coupling's M."""
    M = np.eye(robot.model_dof) if robot.coupling is None else robot.coupling.M
    counts = []
    for tip in robot.tip_frames:
        path, j = [], tip.parent
        while j >= 0:
            path.append(j)
            j = robot.parents[j]
        counts.append(int(np.count_nonzero(np.any(M[path] != 0, axis=0))))
    return counts


def tree_rows(robot: Robot, orientation: bool | None) -> np.ndarray:
    """The rows of tree `robot`'s stacked pose errors (6 per tip, position then rotation,
    tip after tip) that compensation matches.

    Parameters
    ----------
    robot : Robot
        A tree.
    orientation : bool or None
        None: each tip's orientation where six or more controller joints move it
        (`tip_joints`), its position only elsewhere. True: every tip's orientation.
        False: positions only.

    Returns
    -------
    ndarray of int, shape (k,)
        Row indices into the 6 · tips rows, ascending.

    Raises
    ------
    CalibrationError
        ``orientation=True`` with a tip fewer than six joints move; more rows to match
        than the robot has (controller) joints, which no joint values satisfy in general.
    """
    counts = tip_joints(robot)
    if orientation:
        few = [(t, n) for t, n in zip(robot.tips, counts, strict=True) if n < 6]
        if few:
            raise CalibrationError(
                f"tip {few[0][0]!r} of robot {robot.name!r} is moved by {few[0][1]} joints: "
                "too few to set its orientation as well as its position; match positions "
                "only (orientation=False, --position-only), or leave orientation unset to "
                "match each tip's orientation where six or more joints move it"
            )
    rows = []
    for k, n in enumerate(counts):
        full = n >= 6 if orientation is None else bool(orientation)
        rows += range(6 * k, 6 * k + (6 if full else 3))
    if len(rows) > robot.dof:
        # more values to match than joints: no joint values put every tip there, but
        # where the calibrated tree happens to be the nominal one
        what = "positions and orientations" if len(rows) > 3 * len(counts) else "positions"
        hint = (
            "; match positions only (orientation=False, --position-only)"
            if 3 * len(counts) <= robot.dof
            else ""
        )
        raise CalibrationError(
            f"robot {robot.name!r}: its {len(counts)} tips' {what} are {len(rows)} values to "
            f"match and it has {robot.dof} joints: no joint values put every tip where the "
            f"nominal robot does{hint}"
        )
    return np.array(rows, dtype=int)
