"""The robot catalog and robot files: `robots`, `load_robot` (`robot_to_toml` writes them).

A robot file is TOML::

    name = "my_arm"
    convention = "dh"          # "dh" = standard (Rz θ, Tz d, Tx a, Rx α); "mdh" = modified/Craig
    length_unit = "mm"         # "m" (default) or "mm"
    angle_unit = "deg"         # "rad" (default) or "deg"
    [[joints]]                 # one table per joint, base to tip
    type = "R"                 # "R" or "P"
    a = 0.0
    alpha = -90.0
    d = 349.0
    theta = 0.0                # constant offset added to the joint variable (default 0)
    beta = 0.0                 # optional: Hayati's tilt (default: 0 where the axes are parallel)
    limits = [-170.0, 170.0]   # optional, in the file's units (a prismatic joint's in length_unit)
    [base]                     # optional, default identity: xyz in length_unit, rpy in angle_unit
    xyz = [0.0, 0.0, 0.0]
    rpy = [0.0, 0.0, 0.0]      # (rx, ry, rz): R = Rz(rz) Ry(ry) Rx(rx)
    [tool]                     # optional, same form
    xyz = [0.0, 0.0, 0.1]

``points = [[x, y, z], …]`` (top level, length_unit) lists measured points (reflectors) in the
tool frame; without it the tool frame's origin is the measured point. ``full_name``,
``variant``, ``source`` (list of strings) and ``confidence`` are optional descriptions.

An optional ``[plausible]`` table gives the robot's own sizes of a real deviation
(`Robot.with_plausible`), each key naming its unit (whatever length_unit and angle_unit
say)::

    [plausible]                # the largest deviations expected of this robot
    length_mm = 10.0           # or length_m; default 2.5 mm
    angle_deg = 2.0            # or angle_rad; default 0.5°
    "rad/(N·m)" = 1e-4         # other units by name (casecal.model.parameters.UNITS), SI
    [plausible.poorly]         # optional: standard errors above these are poorly determined
    length_mm = 4.0            # default: the plausible size times the default's ratio
    angle_deg = 0.4            # (1 mm / 2.5 mm = 0.4 for lengths, 0.1° / 0.5° = 0.2 for angles)

An optional ``[coupling]`` table gives the model's joints from the controller's (the CSV's
``q1`` … ``qn``), ``q_model = M q + b`` (`casecal.model.coupling`, `Robot.with_coupling`)::

    [coupling]
    q3 = {q2 = -1.0, q3 = -1.0}  # model joint 3 = -(controller joints 2 and 3); others: own
    # controller_joints = 3      # fewer controller joints than model joints (default: as
    # limits = [[-45.0, 45.0], [-30.0, 30.0], []]  # many), then their limits here ([]: none)
    # q4 = {q2 = -1.0, q3 = -1.0, offset = 5.0}   # offset in angle_unit (length_unit: P)
Every mistake raises `CalibrationError` naming the file, the key and the fix.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

from ..errors import CalibrationError
from ..textio import read_text
from .coupling import make_coupling
from .names import catalog_entry, is_path, missing_file, path_text, robots
from .robot import Frame, Joint, Robot
from .terms_toml import TOP_KEYS, add_terms, split_rows
from .toml_out import robot_to_toml  # noqa: F401  (casecal.robot_to_toml lives here)

_LENGTH = {"m": 1.0, "mm": 1e-3}
_ANGLE = {"rad": 1.0, "deg": math.pi / 180.0}
_TOP_KEYS = TOP_KEYS | {
    "points",
    "calibrated_from",
    "calibrated_chain",
    "name",
    "convention",
    "length_unit",
    "angle_unit",
    "joints",
    "base",
    "tool",
    "full_name",
    "variant",
    "source",
    "confidence",
    "description",
    "tips",
    "plausible",
    "coupling",
}
_JOINT_KEYS = {"type", "a", "alpha", "d", "theta", "beta", "limits"}
_FRAME_KEYS = {"xyz", "rpy"}


_FLAGS = {"base_link": "--base-link", "tip_link": "--tip-link"}


def load_robot(
    name_or_path: str | Path,
    base_link: str | None = None,
    tip_link: str | list[str] | tuple[str, ...] | None = None,
    packages: dict[str, str] | None = None,
) -> Robot:
    """Load a robot from the catalog by name, or from a TOML or URDF file by path.

    Parameters
    ----------
    name_or_path : str or path
        A catalog name (see `robots`), the path of a robot file (schema in the module doc),
        of a ``.urdf`` (or ``.xacro``, with the xacro extra) file, or of a UR
        ``kinematics:`` file (``.yaml``, `casecal.model.ur_kinematics`). A string with no
        slash and no suffix is a catalog name only, whatever files the working folder
        holds (``"./arm"`` loads a file named ``arm``); a `pathlib.Path` is always a path
        (rules in `casecal.model.names`).
    base_link, tip_link : str, optional
        URDF only: the chain's ends (defaults in `casecal.model.urdf.read_urdf`).
        `tip_link` a list of several links: the tree of the paths to them, each a
        measured tip (`casecal.model.tree`); a list of one: the chain to it.
    packages : dict of str to str, optional
        xacro only: ROS package name to folder, for ``$(find ...)``.

    Returns
    -------
    Robot
        Numbers converted to SI (m, rad).

    Raises
    ------
    CalibrationError
        Unknown name, missing file, or a malformed file (the message names file and key).
    """
    text = str(name_or_path)
    if not is_path(name_or_path):
        entry = catalog_entry(text)
        _no_ends(text, base_link, tip_link, packages)
        label, source, stem = f"catalog robot {text}", read_text(entry, "robot file"), text
    else:
        path = Path(text)
        suffix = path.suffix.lower()
        if text != "-" and not path.exists():
            raise CalibrationError(missing_file(path))
        if suffix in (".urdf", ".xacro"):
            from .urdf import load_urdf

            return load_urdf(path, base_link, tip_link, packages)
        _no_ends(text, base_link, tip_link, packages)
        if suffix in (".yaml", ".yml"):
            from .ur_kinematics import read_ur_kinematics

            return read_ur_kinematics(read_text(path, "UR kinematics file"), text, path.stem)
        label, source, stem = text, read_text(path, "robot file"), path.stem
    try:
        data = tomllib.loads(source)
    except tomllib.TOMLDecodeError as exc:
        raise CalibrationError(f"{label}: not valid TOML ({exc}); fix the syntax") from None
    return robot_from_dict(data, label=label, default_name=stem)


def _no_ends(text: str, base_link, tip_link, packages) -> None:
    """Refuse the URDF-only arguments for a robot that is not a URDF or xacro file."""
    if base_link is not None or tip_link is not None or packages is not None:
        given = [k for k, v in (("base_link", base_link), ("tip_link", tip_link)) if v]
        flags = f" ({', '.join(_FLAGS[k] for k in given)} on the command line)" if given else ""
        given += ["packages"] if packages is not None else []
        raise CalibrationError(
            f"{'= and '.join(given)}={flags} appl{'ies' if len(given) == 1 else 'y'} to URDF "
            "and xacro robots only, and "
            f"{text!r} is not one; leave them out"
        )


def robot_from_dict(data: dict, label: str = "robot", default_name: str = "robot") -> Robot:
    """Build a Robot from parsed TOML (see the module doc); `label` names it in errors."""
    _no_unknown(data, _TOP_KEYS, label, "top level")
    length = _unit(data, "length_unit", _LENGTH, label)
    angle = _unit(data, "angle_unit", _ANGLE, label)
    if "convention" not in data:
        raise CalibrationError(
            f"{label}: missing key 'convention'; add convention = \"dh\" (standard) or "
            '"mdh" (modified/Craig) - the same numbers mean different robots'
        )
    convention = data["convention"]
    if convention not in ("dh", "mdh", "urdf"):
        raise CalibrationError(
            f'{label}: convention = {convention!r} is unknown; use "dh", "mdh" or "urdf"'
        )
    rows = data.get("joints")
    if not isinstance(rows, list) or not rows or not all(isinstance(r, dict) for r in rows):
        raise CalibrationError(
            f"{label}: missing or empty [[joints]]; add one [[joints]] table per joint"
        )
    rows, inertials = split_rows(rows, length, label, _number)
    parents = ()
    if "tips" in data:  # a tree (`casecal.model.tree`): its joints say what they hang from
        from .tree import toml_parents

        if convention != "urdf" or "tool" in data:
            raise CalibrationError(
                f'{label}: [[tips]] make a tree, which is convention = "urdf" without a '
                "[tool] (each tip has its own frame)"
            )
        rows, parents = toml_parents(rows, label, _number)
    joints = []
    for i, row in enumerate(rows, start=1):
        where = f"joints[{i}]"
        if convention == "urdf":
            from .urdf_toml import joint_from_row

            joints.append(joint_from_row(row, where, length, angle, label, _number))
            continue
        _no_unknown(row, _JOINT_KEYS, label, where)
        jtype = row.get("type")
        if jtype not in ("R", "P"):
            raise CalibrationError(
                f'{label}: {where}.type = {jtype!r}; it must be "R" (revolute) or "P" (prismatic)'
            )
        for key in ("a", "alpha", "d"):
            if key not in row:
                raise CalibrationError(f"{label}: {where} misses key '{key}'; add {key} = <number>")
        limits = None
        if "limits" in row:
            lim = row["limits"]
            if not isinstance(lim, list) or len(lim) != 2:
                raise CalibrationError(f"{label}: {where}.limits must be [min, max]")
            scale = length if jtype == "P" else angle
            lo, hi = (_number(v, label, f"{where}.limits") * scale for v in lim)
            if not lo < hi:
                raise CalibrationError(f"{label}: {where}.limits = {lim}: min must be below max")
            limits = (lo, hi)
        beta = row.get("beta")
        joints.append(
            Joint(
                type=jtype,
                a=_number(row["a"], label, f"{where}.a") * length,
                alpha=_number(row["alpha"], label, f"{where}.alpha") * angle,
                d=_number(row["d"], label, f"{where}.d") * length,
                theta=_number(row.get("theta", 0.0), label, f"{where}.theta") * angle,
                beta=None if beta is None else _number(beta, label, f"{where}.beta") * angle,
                limits=limits,
            )
        )
    name = data.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise CalibrationError(f"{label}: name must be a non-empty string")
    source = data.get("source", ())
    if isinstance(source, str):
        source = (source,)
    elif isinstance(source, list | tuple) and all(isinstance(s, str) for s in source):
        source = tuple(source)
    else:
        raise CalibrationError(f"{label}: source must be a string or a list of strings")
    points = data.get("points", [])
    if not isinstance(points, list) or not all(isinstance(p, list) and len(p) == 3 for p in points):
        raise CalibrationError(
            f"{label}: points must be a list of [x, y, z] in the tool frame, e.g. "
            "points = [[0.0, 0.0, 0.1]]"
        )
    points = tuple(tuple(_number(v, label, "points") * length for v in p) for p in points)
    calibrated_from = data.get("calibrated_from", "")
    if not isinstance(calibrated_from, str):
        raise CalibrationError(f"{label}: calibrated_from must be a robot name or path string")
    # a relative path is relative to this file's folder (identify writes it so)
    # (a catalog name stays a name whatever files lie beside: the rule of load_robot)
    beside = Path(label).parent / calibrated_from
    named = calibrated_from and not is_path(calibrated_from) and calibrated_from in robots()
    if calibrated_from and not named and not Path(calibrated_from).is_absolute():
        if beside.is_file():
            calibrated_from = path_text(beside)
    chain = data.get("calibrated_chain", [])
    if not (isinstance(chain, list) and len(chain) != 1 and all(isinstance(c, str) for c in chain)):
        raise CalibrationError(
            f"{label}: calibrated_chain must be [base_link, tip_link] (a tree: [base_link, "
            "tip, tip, …])"
        )
    tips = ()
    if parents:
        from .tree import toml_tips

        tips = toml_tips(data, len(joints), length, angle, label, _number)
    robot = Robot(
        name=name,
        inertials=inertials,
        calibrated_from=calibrated_from,
        calibrated_chain=tuple(chain),
        points=points,
        joints=tuple(joints),
        convention=convention,
        base=_frame(data, "base", length, angle, label),
        tool=_frame(data, "tool", length, angle, label),
        full_name=str(data.get("full_name", "")),
        source=source,
        confidence=str(data.get("confidence", "")),
        parents=parents,
        tip_frames=tips,
    )
    robot = add_terms(robot, data, angle, label, _number, length)
    sizes = _sizes(data, label)
    robot = dataclasses.replace(robot, sizes=sizes, auto_beta=False) if sizes else robot
    if "coupling" in data:
        robot = _coupling(robot, data["coupling"], length, angle, label)
    return robot


def _coupling(robot: Robot, table, length: float, angle: float, label: str) -> Robot:
    """`robot` with the ``[coupling]`` table of its file (module doc)."""
    import numpy as np

    if not isinstance(table, dict):
        raise CalibrationError(
            f"{label}: coupling must be a table, e.g. [coupling] with q3 = {{q2 = -1.0, q3 = -1.0}}"
        )
    n, types = robot.model_dof, robot.joint_types
    k = table.get("controller_joints", n)
    if isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= n:
        raise CalibrationError(
            f"{label}: coupling.controller_joints = {k!r}; give a whole number from 1 to the "
            f"model's {n} joints"
        )
    rows = [f"q{i}" for i in range(1, n + 1)]
    unknown = sorted(set(table) - {"controller_joints", "limits", *rows})
    if unknown:
        raise CalibrationError(
            f"{label}: unknown key '{unknown[0]}' at [coupling]; allowed keys: "
            f"controller_joints, limits, q1 … q{n} (model joints)"
        )
    M, b = np.zeros((n, k)), np.zeros(n)
    columns = {f"q{j}": j - 1 for j in range(1, k + 1)}
    for i, key in enumerate(rows):
        if key not in table:
            if i >= k:
                raise CalibrationError(
                    f"{label}: [coupling] does not give model joint {key}, and there is no "
                    f"controller joint {key} (controller_joints = {k}); add {key} = {{...}}"
                )
            M[i, i] = 1.0
            continue
        row = table[key]
        if not isinstance(row, dict):
            raise CalibrationError(
                f"{label}: coupling.{key} must be an inline table of controller joints, "
                f"e.g. {key} = {{q2 = -1.0, q3 = -1.0, offset = 0.0}}"
            )
        for name, value in row.items():
            if name == "offset":
                scale = angle if types[i] == "R" else length
                b[i] = _number(value, label, f"coupling.{key}.offset") * scale
            elif name in columns:
                M[i, columns[name]] = _number(value, label, f"coupling.{key}.{name}")
            else:
                raise CalibrationError(
                    f"{label}: coupling.{key} names {name!r}, which is no controller joint "
                    f"(q1 … q{k}) nor offset"
                )
    limits = None
    if "limits" in table:
        lim = table["limits"]
        if not isinstance(lim, list) or len(lim) != k:
            raise CalibrationError(
                f"{label}: coupling.limits must give one [min, max] (or [] for none) per "
                f"controller joint ({k})"
            )
        limits = []
        for c, pair in enumerate(lim):
            driven = np.flatnonzero(M[:, c])
            scale = angle if not driven.size or types[driven[0]] == "R" else length
            if pair == []:
                limits.append(None)
            elif isinstance(pair, list) and len(pair) == 2:
                where = f"coupling.limits[{c + 1}]"
                limits.append(tuple(_number(v, label, where) * scale for v in pair))
            else:
                raise CalibrationError(
                    f"{label}: coupling.limits[{c + 1}] must be [min, max] or [] (no limits)"
                )
    try:
        # a file keeps the limits in one place: rows and [coupling] both is refused here,
        # where `with_coupling` would take a URDF's rows for the controller's
        make_coupling(M, b, limits, robot.joints, f"robot {robot.name!r}")
        return robot.with_coupling(M, b, limits)
    except CalibrationError as exc:
        raise CalibrationError(f"{label}: [coupling]: {exc}") from None


_SIZE_KEYS = {
    "length_m": ("m", 1.0),
    "length_mm": ("m", 1e-3),
    "angle_rad": ("rad", 1.0),
    "angle_deg": ("rad", math.pi / 180.0),
}
"""Keys of a robot file's ``[plausible]`` table: unit and factor to SI (other units by
their `casecal.model.parameters.UNITS` key, in SI)."""


def _sizes(data: dict, label: str) -> tuple:
    """The ``[plausible]`` table of a robot file as `Robot.sizes` (module doc)."""
    from .parameters import UNITS, checked_sizes

    table = data.get("plausible")
    if table is None:
        return ()
    if not isinstance(table, dict):
        raise CalibrationError(
            f"{label}: plausible must be a table, e.g. [plausible] with length_mm = 10.0 and "
            "angle_deg = 2.0"
        )
    poorly = table.get("poorly", {})
    if not isinstance(poorly, dict):
        raise CalibrationError(
            f"{label}: plausible.poorly must be a table, e.g. [plausible.poorly] with "
            "length_mm = 4.0"
        )
    plausible = _size_table({k: v for k, v in table.items() if k != "poorly"}, label, "plausible")
    bounds = _size_table(poorly, label, "plausible.poorly")
    triples = []
    for si in sorted(set(plausible) | set(bounds)):
        default = UNITS[si]
        p = plausible.get(si, default.plausible)
        q = bounds.get(si, p * default.poorly / default.plausible)
        triples.append((si, p, q))
    return checked_sizes(triples, label)


def _size_table(table: dict, label: str, where: str) -> dict:
    from .parameters import UNITS

    out: dict[str, float] = {}
    for key, value in table.items():
        si, scale = _SIZE_KEYS.get(key, (key, 1.0))
        if si not in UNITS:
            raise CalibrationError(
                f"{label}: unknown key '{key}' at [{where}]; allowed keys: "
                f"{', '.join(_SIZE_KEYS)} or a unit by name ({', '.join(map(repr, UNITS))}, SI)"
            )
        if si in out:
            raise CalibrationError(
                f"{label}: [{where}] gives the size of {'lengths' if si == 'm' else 'angles'} "
                "twice; keep one key"
            )
        out[si] = _number(value, label, f"{where}.{key}") * scale
    return out


def load_deviations(path, robot: Robot | None = None) -> dict[str, float]:
    """Read parameter deviations from a TOML file, in SI.

    The file holds ``length_unit`` and ``angle_unit`` as in robot files (default m, rad) and
    one ``name = value`` per parameter, at the top level or under ``[deviations]``::

        length_unit = "mm"
        angle_unit = "deg"
        [deviations]
        theta1 = 0.01
        a2 = -0.2

    Parameters
    ----------
    path : str or path
    robot : Robot, optional
        When given, every name must be one of its parameters.

    Returns
    -------
    dict of str to float
        Deviations in m and rad.
    """
    from .parameters import unit

    label = str(path)
    try:
        data = tomllib.loads(read_text(path, "deviations file"))
    except tomllib.TOMLDecodeError as exc:
        raise CalibrationError(f"{label}: not valid TOML ({exc}); fix the syntax") from None
    length = _unit(data, "length_unit", _LENGTH, label)
    angle = _unit(data, "angle_unit", _ANGLE, label)
    table = data.get("deviations", {k: v for k, v in data.items() if not k.endswith("_unit")})
    if not isinstance(table, dict) or not table:
        raise CalibrationError(f"{label}: no deviations found; write e.g. theta1 = 0.01")
    known = set(robot.parameter_names) if robot is not None else None
    out = {}
    for name, value in table.items():
        if known is not None and name not in known:
            raise CalibrationError(
                f"{label}: {name!r} is not a parameter of robot {robot.name!r}; "
                f"its parameters are: {', '.join(robot.parameter_names)}"
            )
        # compliance terms (rad/(N·m), rad/m) are SI whatever the file's units; the rest,
        # lumped gravity moments (rad) too, in the file's units as tables show them
        scale = {"m": length, "rad": angle}.get(unit(name), 1.0)
        out[name] = _number(value, label, name) * scale
    return out


def _no_unknown(table: dict, allowed: set, label: str, where: str) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise CalibrationError(
            f"{label}: unknown key '{unknown[0]}' at {where}; "
            f"allowed keys: {', '.join(sorted(allowed))}"
        )


def _unit(data: dict, key: str, table: dict, label: str) -> float:
    value = data.get(key, next(iter(table)))
    if not isinstance(value, str) or value not in table:
        raise CalibrationError(
            f"{label}: {key} = {value!r} is unknown; use one of {', '.join(map(repr, table))}"
        )
    return table[value]


def _number(value, label: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise CalibrationError(f"{label}: {where} = {value!r} is not a number; write a number")
    try:
        number = float(value)  # a 401-digit integer does not fit a float
    except OverflowError:
        number = math.inf
    if not math.isfinite(number) or (number != 0 and abs(number) > 1e12):
        shown = (
            f"{value:.6g}"
            if isinstance(value, float)
            else f"an integer of {len(str(abs(value)))} digits"
        )
        raise CalibrationError(
            f"{label}: {where} = {shown} is not a size a robot has; write a finite number in "
            "the file's units"
        )
    return number


def _frame(data: dict, key: str, length: float, angle: float, label: str) -> Frame:
    table = data.get(key)
    if table is None:
        return Frame()
    if not isinstance(table, dict):
        raise CalibrationError(f"{label}: [{key}] must be a table with xyz and rpy")
    _no_unknown(table, _FRAME_KEYS, label, f"[{key}]")
    out = {}
    for sub, scale in (("xyz", length), ("rpy", angle)):
        v = table.get(sub, [0.0, 0.0, 0.0])
        if not isinstance(v, list) or len(v) != 3:
            raise CalibrationError(f"{label}: [{key}].{sub} must be a list of three numbers")
        out[sub] = tuple(_number(x, label, f"[{key}].{sub}") * scale for x in v)
    return Frame(out["xyz"], out["rpy"])


def nominal_of(robot: Robot) -> Robot:
    """The nominal robot `robot` was calibrated from (its ``calibrated_from``, with the
    URDF chain it used)."""
    if not robot.calibrated_from:
        raise CalibrationError(
            f"robot {robot.name!r} does not say which nominal robot it was calibrated from "
            "(no calibrated_from); give the nominal robot"
        )
    chain = robot.calibrated_chain
    # a tree's: the base link and its tips
    chain = (chain[0], list(chain[1:])) if len(chain) > 2 else chain
    ends = dict(zip(("base_link", "tip_link"), chain, strict=False))
    try:
        return load_robot(robot.calibrated_from, **ends)
    except CalibrationError as exc:
        raise CalibrationError(
            f"the nominal robot {robot.calibrated_from!r} (calibrated_from) cannot be loaded: "
            f"{exc}; give it explicitly"
        ) from None
