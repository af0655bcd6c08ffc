"""Robot files written: `robot_to_toml`, the schema `casecal.model.catalog` reads."""

from __future__ import annotations

import numpy as np

from .robot import Robot
from .terms_toml import inertial_lines, terms_lines


def robot_to_toml(robot: Robot) -> str:
    """Write `robot` as a robot file (m, rad, full precision) that `load_robot` reads back."""
    lines = [f"name = {_q(robot.name)}"]
    if robot.full_name:
        lines.append(f"full_name = {_q(robot.full_name)}")
    lines += [f"convention = {_q(robot.convention)}", 'length_unit = "m"', 'angle_unit = "rad"']
    if robot.source:
        lines.append("source = [" + ", ".join(_q(s) for s in robot.source) + "]")
    if robot.confidence:
        lines.append(f"confidence = {_q(robot.confidence)}")
    if robot.calibrated_from:
        lines.append(f"calibrated_from = {_q(robot.calibrated_from)}")
        chain = robot.calibrated_chain or (
            (robot.urdf.base_link, robot.urdf.tip_link) if robot.urdf is not None else ()
        )
        if chain and not isinstance(chain[1], str):  # a tree's tips
            chain = (chain[0], *chain[1])
        if chain:
            lines.append(f"calibrated_chain = [{', '.join(_q(c) for c in chain)}]")
    for i, j in enumerate(robot.joints):
        if robot.convention == "urdf":
            from .urdf_toml import joint_to_lines

            lines += ["", "[[joints]]", *joint_to_lines(j, _q), *inertial_lines(robot, i)]
            if robot.is_tree:
                from .tree import toml_lines

                lines += toml_lines(robot, i)
            continue
        lines += [
            "",
            "[[joints]]",
            f"type = {_q(j.type)}",
            f"a = {float(j.a)!r}",
            f"alpha = {float(j.alpha)!r}",
            f"d = {float(j.d)!r}",
            f"theta = {float(j.theta)!r}",
        ]
        if j.beta is not None:
            lines.append(f"beta = {float(j.beta)!r}")
        if j.limits is not None:
            lines.append(f"limits = [{float(j.limits[0])!r}, {float(j.limits[1])!r}]")
        lines += inertial_lines(robot, i)
    if robot.points:
        rows = ", ".join("[" + ", ".join(repr(float(v)) for v in p) + "]" for p in robot.points)
        lines.insert(lines.index('angle_unit = "rad"') + 1, f"points = [{rows}]")
    if robot.is_tree:
        from .tree import toml_tip_lines

        lines += toml_tip_lines(robot, _q)
    frames = (("base", robot.base), ("tool", robot.tool))
    for key, frame in frames[:1] if robot.is_tree else frames:  # a tree's tips: its tools
        lines += [
            "",
            f"[{key}]",
            f"xyz = [{', '.join(repr(float(v)) for v in frame.xyz)}]",
            f"rpy = [{', '.join(repr(float(v)) for v in frame.rpy)}]",
        ]
    extra = terms_lines(robot)
    top = 0  # top-level keys (gravity, inputs, payload_com) go before the first table
    while top < len(extra) and extra[top]:
        top += 1
    at = lines.index('angle_unit = "rad"') + 1
    lines[at:at] = extra[:top]
    lines += extra[top:] + _coupling_lines(robot) + _sizes_lines(robot)
    return "\n".join(lines) + "\n"


def _coupling_lines(robot: Robot) -> list[str]:
    """The robot's joint coupling as a ``[coupling]`` table (SI, like the rest of the file):
    the model joints that are not their controller joint's own."""
    c = robot.coupling
    if c is None:
        return []
    lines = ["", "[coupling]  # model joints from the controller's: q_model = M q + b"]
    if not c.square:
        lines.append(f"controller_joints = {c.n_controller}")
    M, b = c.M, c.b
    for i in range(c.n_model):
        if i < c.n_controller and M[i, i] == 1 and np.count_nonzero(M[i]) == 1 and b[i] == 0:
            continue  # the controller joint of its number: the default
        items = [f"q{j + 1} = {float(v)!r}" for j, v in enumerate(M[i]) if v != 0]
        if b[i] != 0:
            items.append(f"offset = {float(b[i])!r}")
        lines.append(f"q{i + 1} = {{{', '.join(items)}}}")
    if c.limits:
        rows = ", ".join(
            "[]" if lim is None else f"[{float(lim[0])!r}, {float(lim[1])!r}]" for lim in c.limits
        )
        lines.append(f"limits = [{rows}]")
    return lines


def _sizes_lines(robot: Robot) -> list[str]:
    """The robot's own sizes (`Robot.sizes`) as a ``[plausible]`` table, SI to the last
    digit (the comment gives mm and degrees); none for the defaults."""
    if not robot.sizes:
        return []
    from .parameters import UNITS

    keys = {"m": "length_m", "rad": "angle_rad"}

    def table(header: str, index: int) -> list[str]:
        rows = ["", header]
        for si, *values in robot.sizes:
            facts, value = UNITS[si], values[index]
            key = keys.get(si, _q(si))
            unit = "°" if facts.shown == "deg" else " " + facts.shown
            shown = f"{value * facts.factor:.6g}{unit}"
            rows.append(f"{key} = {float(value)!r}  # {shown}")
        return rows

    return table("[plausible]", 0) + table("[plausible.poorly]", 1)


def _q(text: str) -> str:
    escaped = text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
    return f'"{escaped}"'
