"""`save_robot`: a robot file in the format its extension names, read back and verified."""

from __future__ import annotations

import dataclasses
import tomllib
import warnings
from pathlib import Path

from ..errors import CalibrationError
from .export_check import Contract, Export, ExportLossWarning, verified


def export(robot, path) -> Export:
    """The text `save_robot` writes to `path`, checked by reading it back.

    The text is read back in memory with casecal's own reader and its forward kinematics
    compared with `robot`'s (`casecal.model.export_check`): the returned `Export` says in
    mm and degrees what the file loses, if anything, and why.

    Raises
    ------
    CalibrationError
        An unknown extension, a robot the format cannot describe at all, or a text that
        reads back other than it should (a bug: nothing is to be written).
    """
    if robot.sessions:
        # a file holds one base frame: the others would be lost without a word
        raise CalibrationError(
            f"robot {robot.name!r} has frames of {len(robot.sessions) + 1} measurement "
            "sessions and a robot file holds one; save the calibrated robot "
            "(Calibration.robot, with the first session's frames)"
        )
    suffix = Path(path).suffix.lower()
    if suffix == ".toml":
        from .catalog import robot_from_dict, robot_to_toml

        def read(text):
            try:
                data = tomllib.loads(text)
            except tomllib.TOMLDecodeError as exc:
                raise CalibrationError(f"not valid TOML ({exc})") from None
            return robot_from_dict(data, str(path), Path(path).stem)

        text, notes = robot_to_toml(robot), []
        contract = Contract("a TOML robot file", robot, robot, read)
    elif suffix in (".urdf", ".yaml", ".yml"):
        if suffix != ".urdf" and robot.is_tree:
            raise CalibrationError(
                f"{path}: a UR kinematics file holds one arm, and robot {robot.name!r} is a "
                "tree with several tips; save it as .urdf or .toml"
            )
        if robot.coupling is not None:
            what = "a URDF" if suffix == ".urdf" else "a UR kinematics file"
            raise CalibrationError(
                f"{path}: robot {robot.name!r} couples its joints "
                f"({'; '.join(robot.coupling.describe(robot.joint_types))}, from the "
                f"controller's joints): {what} cannot hold that, and without it the file "
                "would take the controller's joint values for the model's; not written: save "
                "as .toml, which keeps the coupling"
            )
        if suffix == ".urdf":
            from .urdf_out import robot_to_urdf as writer
            from .urdf_out import urdf_contract as contract_of
        else:
            from .ur_kinematics import ur_kinematics_contract as contract_of
            from .ur_kinematics import ur_kinematics_text as writer
        text, notes = writer(robot)
        if robot.sizes:  # no kinematics, so no loss the read-back check could see
            from .parameters import sizes_text

            notes = [
                *notes,
                f"the robot's own sizes of a real deviation ({sizes_text(robot.sizes)}) "
                "have no place in this file and are not written: a fit of the robot read "
                "from it uses the industrial defaults; save as .toml to keep them, or give "
                "them again (Robot.with_plausible, identify --plausible-length-mm and "
                "--plausible-angle-deg)",
            ]
        contract = contract_of(robot, str(path))
        if robot.terms:
            names = ", ".join(sorted({t.kind.replace("_", " ") for t in robot.terms}))
            contract = dataclasses.replace(
                contract,
                terms_reason=(
                    f"the error terms beyond geometry ({names}) cannot go into this file and "
                    "are not written: the controller will not apply them; save as .toml to "
                    "keep them, and use casecal compensate, which applies the full model"
                ),
            )
    elif str(path) == "-":
        raise CalibrationError(
            "a robot file cannot go to standard output ('-'): its format comes from the "
            "file name's extension; give a name ending in .toml, .urdf or .yaml (UR kinematics)"
        )
    else:
        raise CalibrationError(
            f"{path}: unknown robot file type {suffix or '(no extension)'}; use .toml, .urdf "
            "or .yaml (UR kinematics)"
        )
    return verified(path, text, notes, contract)


def robot_text(robot, path) -> tuple[str, list[str]]:
    """The text `save_robot` writes to `path` (verified, `export`), and notes on what that
    format cannot hold: the loss in mm and degrees first when there is one."""
    out = export(robot, path)
    return out.text, list(out.notes)


def save_robot(robot, path, *, strict: bool = False) -> list[str]:
    """Write `robot` to `path` (atomically) as TOML (``.toml``), URDF (``.urdf``) or a UR
    kinematics file (``.yaml``, `casecal.model.ur_kinematics`), verified on write.

    A robot read from a URDF is written into its own file's text with only the calibrated
    numbers changed; a DH robot as a new URDF of its chain (`casecal.model.urdf_out`).

    Before the file replaces anything its text is read back with casecal's own reader and
    its forward kinematics compared with `robot`'s at 300 poses across the joint ranges
    (tool position and orientation, every measured point; the base frame left out of both
    for URDF and UR files, which do not hold it). A TOML file holds everything; a URDF or a
    UR kinematics file may not (error terms, a UR tool beyond ``wrist_3_link``): the loss
    is then stated in mm and degrees, with what to do about it.

    Parameters
    ----------
    robot : Robot
    path : str or path
    strict : bool
        False (default): a file that loses something is written, and the loss is said in
        the returned notes and as an `ExportLossWarning` (a `casecal.CalibrationWarning`).
        True: such a file is not written; `CalibrationError` says the loss instead.

    Returns
    -------
    list of str
        What the format could not hold and where it went, one sentence each, the loss in
        mm and degrees first (empty for TOML, which holds everything).

    Raises
    ------
    CalibrationError
        An unknown extension, a robot the format cannot describe, a loss with
        ``strict=True``, a text that does not read back as it should (a bug in casecal;
        nothing is written) or a write the system refused.

    Warns
    -----
    ExportLossWarning
        With ``strict=False``, when the file does not hold the whole robot (its ``loss``
        attribute: the largest difference, m and rad).
    """
    from ..textio import write_atomic

    out = export(robot, path)
    if out.statement:
        message = f"{path}: {out.statement}"
        if strict:
            raise CalibrationError(
                f"{message}; not written (strict=True): save as .toml to keep everything, "
                "or pass strict=False to write it with this loss"
            )
        warnings.warn(ExportLossWarning(message, str(path), out.loss), stacklevel=2)
    write_atomic(path, out.text)
    return list(out.notes)
