"""`save_robot`: a robot file in the format its extension names."""

from __future__ import annotations

from pathlib import Path

from ..errors import CalibrationError


def robot_text(robot, path) -> tuple[str, list[str]]:
    """The text `save_robot` writes to `path`, and notes on what that format cannot hold."""
    suffix = Path(path).suffix.lower()
    if suffix == ".toml":
        from .catalog import robot_to_toml

        return robot_to_toml(robot), []
    if suffix in (".urdf", ".yaml", ".yml"):
        if suffix == ".urdf":
            from .urdf_out import robot_to_urdf as writer
        else:
            from .ur_kinematics import ur_kinematics_text as writer
        text, notes = writer(robot)
        if robot.terms:
            names = ", ".join(sorted({t.kind.replace("_", " ") for t in robot.terms}))
            notes.append(
                f"the error terms beyond geometry ({names}) cannot go into this file and are "
                "not written: the controller will not apply them; save as .toml to keep them, "
                "and use casecal compensate, which applies the full model"
            )
        return text, notes
    raise CalibrationError(
        f"{path}: unknown robot file type {suffix!r}; use .toml, .urdf or .yaml (UR kinematics)"
    )


def save_robot(robot, path) -> list[str]:
    """Write `robot` to `path` (atomically) as TOML (``.toml``), URDF (``.urdf``) or a UR
    kinematics file (``.yaml``, `casecal.model.ur_kinematics`).

    A robot read from a URDF is written into its own file's text with only the calibrated
    numbers changed; a DH robot as a new URDF of its chain (`casecal.model.urdf_out`).

    Returns
    -------
    list of str
        What the format could not hold and where it went, one sentence each (empty for
        TOML, which holds everything).
    """
    from ..textio import write_atomic

    text, notes = robot_text(robot, path)
    write_atomic(path, text)
    return notes
