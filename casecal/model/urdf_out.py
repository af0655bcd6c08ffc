"""Robots out as URDF: the input file with only the calibrated numbers changed, or a new
URDF of a DH chain.

A URDF has no joint offset and no instrument frame: a calibrated offset is folded into its
joint's origin (exact: the origin turns about the joint's own axis), the tool frame into
the last fixed joint after the chain when there is one, and what cannot be written (the
base frame, measured points) is returned as notes for the caller to say.
"""

from __future__ import annotations

import re
from xml.sax.saxutils import escape as xml_escape

import numpy as np

from ..errors import CalibrationError
from .urdf import PassiveJoint, chain_path, parse, split, transform


def _attr(text: str) -> str:
    """`text` for a double-quoted XML attribute."""
    return xml_escape(str(text), {'"': "&quot;"})


def _fmt(values) -> str:
    return " ".join(repr(float(v)) if v != 0 else "0" for v in values)


def _rotation_about(axis, angle: float) -> np.ndarray:
    k = np.asarray(axis, dtype=float)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    T = np.eye(4)
    T[:3, :3] = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    return T


def _masked(text: str) -> str:
    """`text` with comments and CDATA blanked (same length): what the parser reads."""
    return re.sub(
        r"<!--.*?-->|<!\[CDATA\[.*?\]\]>", lambda m: " " * len(m.group(0)), text, flags=re.S
    )


def _set_origin(text: str, joint: str, xyz, rpy) -> str:
    """`text` with the origin of the kinematic ``<joint name="joint" type=...>`` (not a
    transmission's joint, not one in a comment) set to `xyz`, `rpy`."""
    seen = _masked(text)
    names = "|".join(re.escape(n) for n in {joint, xml_escape(joint, {'"': "&quot;"})})
    start = re.search(
        r"<joint\b(?=[^>]*\btype\s*=)[^>]*\bname\s*=\s*([\"'])(?:" + names + r")\1[^>]*>", seen
    )
    if start is None:
        raise CalibrationError(
            f"joint {joint!r} is not found in the URDF text it came from; save as .toml instead"
        )
    end = seen.find("</joint>", start.end())
    origin = f'xyz="{_fmt(xyz)}" rpy="{_fmt(rpy)}"'
    found = re.search(r"<origin\b([^>]*?)(/?)>", seen[start.end() : end], flags=re.S)
    if found is None:
        return text[: start.end()] + f"\n    <origin {origin}/>" + text[start.end() :]
    a, b = start.end() + found.start(1), start.end() + found.end(1)
    attrs = re.sub(r"\s*\b(xyz|rpy)\s*=\s*([\"']).*?\2", "", text[a:b], flags=re.S)
    head = start.end() + found.start()
    return (
        text[:head]
        + f"<origin {origin}{attrs}{found.group(2)}>"
        + text[start.end() + found.end() :]
    )


def file_origins(robot) -> tuple[dict[str, np.ndarray], list]:
    """Each movable joint's origin in its URDF file's own frames (4 × 4, with its offset
    folded in), and the fixed joints after the last movable one (`robot` from a URDF)."""
    source = robot.urdf
    _, joints = parse(source.text, "URDF")
    path, _, _ = chain_path(joints, source.base_link, source.tip_link, "URDF")
    movable = {j.name: j for j in robot.joints}
    movable.update({m.name: m for j in robot.joints for m in j.passive})
    origins, pending, fixed_after = {}, np.eye(4), []
    for j in path:
        if j.name not in movable:
            pending = pending @ j.T
            fixed_after.append(j)
            continue
        cj = movable[j.name]
        # a mimic joint's offset is its own (in <mimic>), not a calibrated zero offset
        turn = 0.0 if isinstance(cj, PassiveJoint) else cj.offset
        T = transform(cj.xyz, cj.rpy) @ _rotation_about(cj.axis, turn)
        origins[j.name] = np.linalg.inv(pending) @ T
        pending, fixed_after = np.eye(4), []
    return origins, fixed_after


def offset_note(robot, where: str) -> list[str]:
    """The note for calibrated joint offsets folded into origins, if there are any."""
    offsets = [j.name for j in robot.joints if getattr(j, "offset", 0.0)]
    if not offsets:
        return []
    return [
        f"{where} has no joint offset: the calibrated offsets of {', '.join(offsets)} are "
        "folded into their joints' origins (exact)"
    ]


def calibrated_urdf(robot) -> tuple[str, list[str]]:
    """The URDF text of `robot` (read from a URDF) with its calibrated numbers, and notes.

    Returns
    -------
    text : str
    notes : list of str
        What the file cannot hold and where it went instead (one sentence each).
    """
    origins, fixed_after = file_origins(robot)
    text = robot.urdf.text
    for name, T in origins.items():
        text = _set_origin(text, name, *split(T))
    notes = offset_note(robot, "a URDF")
    tool = transform(robot.tool.xyz, robot.tool.rpy)
    if fixed_after:
        before = np.eye(4)
        for j in fixed_after[:-1]:
            before = before @ j.T
        xyz, rpy = split(np.linalg.inv(before) @ tool)
        text = _set_origin(text, fixed_after[-1].name, xyz, rpy)
    # else the tool frame has no joint to go into: the check on write measures and states
    # it (`urdf_contract`)
    if not np.allclose(transform(robot.base.xyz, robot.base.rpy), np.eye(4), rtol=0, atol=1e-15):
        notes.append(
            "the base frame (instrument to the base link) is not part of the robot and is "
            "not written; save the robot as .toml to keep it"
        )
    if robot.points:
        notes.append(
            "the measured points (reflectors) are not written: a URDF has no place for them"
        )
    return text, notes


def _dh_pieces(robot, i: int) -> tuple[np.ndarray, np.ndarray]:
    """(Pre, Post) of joint `i` (0-based): link = Pre · Motion(q) · Post, motion along z."""

    def rz(t):
        return transform((0, 0, 0), (0, 0, t))

    def rx(t):
        return transform((0, 0, 0), (t, 0, 0))

    def ry(t):
        return transform((0, 0, 0), (0, t, 0))

    def tr(x, z):
        return transform((x, 0, z), (0, 0, 0))

    j = robot.joints[i]
    beta = ry(j.beta or 0.0)
    if robot.convention == "dh":
        if j.type == "R":
            return rz(j.theta), tr(0, j.d) @ tr(j.a, 0) @ rx(j.alpha) @ beta
        return rz(j.theta) @ tr(0, j.d), tr(j.a, 0) @ rx(j.alpha) @ beta
    head = rx(j.alpha) @ beta @ tr(j.a, 0) @ rz(j.theta)
    if j.type == "R":
        return head, tr(0, j.d)
    return head @ tr(0, j.d), np.eye(4)


def _chain_rows(robot):
    """Per joint, mimic joints included, (name, kind letter, origin T, axis, limits, mimic),
    and the transform left over after the last joint (to be followed by the tool frame)."""
    rows, post = [], np.eye(4)
    for i, j in enumerate(robot.joints):
        if robot.convention == "urdf":
            for m in j.passive:
                mimic = (robot.joints[m.master].name, m.multiplier, m.offset)
                # a URDF needs limits on a prismatic joint; a mimic joint's follow its master
                limits = None if m.type == "R" else (-10.0, 10.0)
                rows.append((m.name, m.type, transform(m.xyz, m.rpy), m.axis, limits, mimic))
            T = transform(j.xyz, j.rpy) @ _rotation_about(j.axis, j.offset)
            rows.append((j.name, j.type, T, j.axis, j.limits, None))
            continue
        pre, after = _dh_pieces(robot, i)
        rows.append((f"joint{i + 1}", j.type, post @ pre, (0.0, 0.0, 1.0), j.limits, None))
        post = after
    return rows, post


def new_urdf(robot) -> tuple[str, list[str]]:
    """A URDF of `robot`'s chain: base_link, one link per joint, tool0; a ``world`` link
    when the base frame is not the identity. DH joints turn (or slide) about their z axes."""
    rows, post = _chain_rows(robot)
    links = ["base_link", *(f"link{i}" for i in range(1, len(rows) + 1)), "tool0"]
    base = transform(robot.base.xyz, robot.base.rpy)
    world = not np.allclose(base, np.eye(4), rtol=0, atol=1e-15)
    lines = ['<?xml version="1.0"?>', f'<robot name="{_attr(robot.name)}">']
    lines += [f'  <link name="{name}"/>' for name in (["world"] if world else []) + links]

    def joint(name, kind, parent, child, T, axis=None, limits=None, mimic=None):
        xyz, rpy = split(T)
        out = [
            f'  <joint name="{_attr(name)}" type="{kind}">',
            f'    <parent link="{parent}"/>',
            f'    <child link="{child}"/>',
            f'    <origin xyz="{_fmt(xyz)}" rpy="{_fmt(rpy)}"/>',
        ]
        if axis is not None:
            out.append(f'    <axis xyz="{_fmt(axis)}"/>')
        if limits is not None:
            out.append(
                f'    <limit lower="{float(limits[0])!r}" upper="{float(limits[1])!r}" '
                'effort="0" velocity="0"/>'
            )
        if mimic is not None:
            out.append(
                f'    <mimic joint="{_attr(mimic[0])}" multiplier="{float(mimic[1])!r}" '
                f'offset="{float(mimic[2])!r}"/>'
            )
        return [*out, "  </joint>"]

    if world:
        lines += joint("world_to_base", "fixed", "world", "base_link", base)
    for i, (name, letter, T, axis, limits, mimic) in enumerate(rows):
        if letter == "P" and limits is None:
            raise CalibrationError(
                f"robot {robot.name!r}: prismatic joint {name!r} has no limits, which a URDF "
                "needs; give it limits (limits = [min, max] in its [[joints]] table)"
            )
        kind = "prismatic" if letter == "P" else ("revolute" if limits else "continuous")
        lines += joint(name, kind, links[i], links[i + 1], T, axis, limits, mimic)
    tool = post @ transform(robot.tool.xyz, robot.tool.rpy)
    lines += joint("tool", "fixed", links[-2], "tool0", tool)
    lines.append("</robot>")
    notes = ["the measured points (reflectors) are not written"] if robot.points else []
    if world:
        notes.append(
            "the base frame (instrument to the base) is written as the fixed joint "
            "world_to_base from a link 'world'; load with base_link='base_link' to leave it out"
        )
    return "\n".join(lines) + "\n", notes


def robot_to_urdf(robot) -> tuple[str, list[str]]:
    """URDF text of `robot` and notes on what it cannot hold (see the module doc); a tree
    (several tips) into its own URDF text (`casecal.model.tree.tree_urdf`)."""
    if robot.is_tree:
        from .tree import tree_urdf

        return tree_urdf(robot)
    if robot.urdf is not None:
        return calibrated_urdf(robot)
    return new_urdf(robot)


def urdf_contract(robot, label: str):
    """What a URDF of `robot` holds (`casecal.model.export_check.Contract`), read back with
    the same chain: for a robot from a URDF its base link to its tip link, compared in its
    base frame (a URDF has no place for the instrument's); for a new URDF the root (the
    ``world`` link that holds the base frame, when there is one) to ``tool0``. The tool
    frame goes into the last fixed joint of the chain; a chain that ends at a movable
    joint has none to hold it.
    """
    import dataclasses

    from .export_check import Contract
    from .robot import Frame
    from .urdf import read_urdf

    if robot.is_tree:
        from .tree import tree_contract

        return tree_contract(robot, label)
    if robot.urdf is None:
        reference, held = robot, dataclasses.replace(robot, terms=(), auto_beta=False)
        ends, reason = (None, "tool0"), ""
    else:
        source = robot.urdf
        reference = dataclasses.replace(robot, base=Frame(), auto_beta=False)
        held = dataclasses.replace(reference, terms=(), auto_beta=False)
        ends, reason = (source.base_link, source.tip_link), ""
        if not file_origins(robot)[1]:
            held = dataclasses.replace(held, tool=Frame(), auto_beta=False)
            reason = (
                f"the tool frame is not written: the chain ends at the movable joint "
                f"{robot.joints[-1].name!r} (tip link {source.tip_link!r}), and a URDF has no "
                "fixed joint there to hold it; add a fixed joint to a tool link in the URDF "
                "and load it with tip_link= that link, or save as .toml"
            )

    def read(text: str):
        back = read_urdf(text, label, *ends)
        return dataclasses.replace(back, points=robot.points, auto_beta=False)

    return Contract("a URDF", reference, held, read, tool_reason=reason)
