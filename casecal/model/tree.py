"""Robots as kinematic trees: several measured tips on one URDF robot.

A humanoid's two hands, a dual-arm cell, a marker on the chest and one on each wrist: every
tip is measured, and the joints on the way to several tips (a torso) are one set of
parameters, shared by them all. ``load_robot("robot.urdf", tip_link=["right_marker",
"left_marker"])`` reads one (`read_tree`); a list of one link is the serial chain to it.

The tree is the union of the paths from the base link (default: the root) to the tips:

- **Joints**: every actuated movable joint on it, in depth-first order from the base link,
  the children of a link in the file's order (the first child's whole subtree before the
  second child). Joint values (arrays, the ``q1`` … columns of CSV files) follow this order.
  Each joint hangs from the last actuated joint above it (`Robot.parents`: its index, or -1
  for the base).
- **Fixed joints** fold into the next actuated joint's origin along each branch, exactly as
  on a serial chain (`casecal.model.urdf.read_urdf`): a fixed joint above a branch point
  goes into the first joint of every branch below it. Those after a branch's last
  actuated joint make that tip's frame (`Tip`), which takes the place of the serial tool
  frame: parameters ``{tip}.x`` … ``{tip}.yaw`` (`casecal.model.parameters`).
- **Mimic joints** are walked before the next actuated joint of their branch, as on a
  serial chain; one above a branch point (walked in two branches) is refused.

The kinematic graph walks each joint once, from the frame of the joint it hangs from
(`casecal.model.chainwalk.walk_tree`). ``Robot.position(q)`` is then (N, tips, 3) and
``Robot.fk(q)`` (N, tips, 4, 4); measurements of a tree are (N, tips, 3), one point per tip,
and `casecal.identify` fits them all in one problem.

**Masses and error terms.** Each joint's body is its child link with everything it carries
rigidly: the links after it through fixed joints, and branches off the tree (links no
measured tip lies beyond, a head) at their joints' zero; their URDF ``<inertial>`` masses
make `Robot.inertials`. Error terms work as on a serial chain, and a joint's gravity torque
(`Robot.with_compliance`) comes from every body it carries, across branches: the torso
bends under both arms. Measured points on a tip (`Robot.points`), per-pose inputs (a
payload), orientation measurements and distance data are refused for now. Compensation
brings every tip to the nominal tree's pose of it at once (`casecal.model.compensate_tree`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CalibrationError
from .urdf import (
    PassiveJoint,
    UrdfJoint,
    UrdfSource,
    _passive,
    check_joints,
    parse,
    split,
    transform,
)
from .urdf_tree import MOVABLE, chain_path


@dataclass(frozen=True)
class Tip:
    """A measured tip of a tree: the origin of its link, fixed to the frame of a joint.

    Attributes
    ----------
    name : str
        The tip link's name in the URDF; it names the tip's parameters (``{name}.x`` …)
        and measurement columns (``{name}_x_mm`` …).
    parent : int
        0-based index of the actuated joint whose moved frame the tip rides on.
    xyz, rpy : (float, float, float)
        The tip's frame in that joint's frame: m, and roll, pitch, yaw in rad (the fixed
        joints after the branch's last actuated joint, folded together).
    """

    name: str
    parent: int
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        """The tip's frame in its joint's, shape (4, 4)."""
        return transform(self.xyz, self.rpy)


def check_tree(robot) -> None:
    """Raise CalibrationError unless `robot`'s joints, `parents` and `tip_frames` make a
    tree casecal can model (module doc); normalise them to tuples."""
    from .robot import Frame

    name = robot.name
    if robot.convention != "urdf":
        raise CalibrationError(
            f"robot {name!r}: a tree (several tips) is a URDF robot; give convention='urdf' "
            "and URDF joints, or load it from a URDF with tip_link= a list of links"
        )
    refused = [
        what
        for what, present in (
            ("measured points on a tool (points)", robot.points),
            ("per-pose inputs", robot.inputs),
        )
        if present
    ]
    if refused:
        from .kinematics import tree_refusal

        raise tree_refusal(" and ".join(refused))
    if robot.tool != Frame():
        raise CalibrationError(
            f"robot {name!r}: a tree has no tool frame: each tip has its own frame "
            "({tip}.x … {tip}.yaw); set the tips' frames instead"
        )
    joints = tuple(robot.joints)
    check_joints(name, joints)
    try:
        parents = tuple(int(p) for p in robot.parents)
    except (TypeError, ValueError):
        raise CalibrationError(f"robot {name!r}: parents must be joint indices") from None
    if len(parents) != len(joints) or any(not -1 <= p < i for i, p in enumerate(parents)):
        raise CalibrationError(
            f"robot {name!r}: a tree needs one parent per joint, each -1 (the base) or the "
            "index of a joint before it (depth-first order); got "
            f"{list(robot.parents)} for {len(joints)} joints"
        )
    tips = tuple(robot.tip_frames)
    if not tips:
        raise CalibrationError(f"robot {name!r}: a tree needs its tips (tip_frames)")
    taken = {j.name for j in joints} | {p.name for j in joints for p in j.passive}
    seen: set[str] = set()
    for tip in tips:
        if not isinstance(tip, Tip) or not isinstance(tip.name, str) or not tip.name:
            raise CalibrationError(f"robot {name!r}: every tip must be a casecal Tip with a name")
        if tip.name in taken:
            raise CalibrationError(
                f"robot {name!r}: tip {tip.name!r} has the name of a joint; its parameters "
                f"({tip.name}.x …) would be that joint's: rename the link or the joint"
            )
        if tip.name in seen:
            raise CalibrationError(f"robot {name!r}: tip {tip.name!r} is given twice")
        seen.add(tip.name)
        if not isinstance(tip.parent, int | np.integer) or not 0 <= tip.parent < len(joints):
            raise CalibrationError(
                f"robot {name!r}: tip {tip.name!r} must ride on one of its {len(joints)} "
                f"joints (parent 0 … {len(joints) - 1}), not {tip.parent!r}"
            )
        values = [*tip.xyz, *tip.rpy]
        if len(tip.xyz) != 3 or len(tip.rpy) != 3 or not all(math.isfinite(v) for v in values):
            raise CalibrationError(
                f"robot {name!r}, tip {tip.name!r}: xyz and rpy need 3 finite numbers"
            )
    object.__setattr__(robot, "parents", parents)
    object.__setattr__(
        robot,
        "tip_frames",
        tuple(
            Tip(t.name, int(t.parent), tuple(map(float, t.xyz)), tuple(map(float, t.rpy)))
            for t in tips
        ),
    )


def tip_links(tip_link, label: str) -> list[str]:
    """`tip_link` given as a list or tuple, checked: link names, each once."""
    tips = list(tip_link)
    if not tips:
        raise CalibrationError(
            f"{label}: tip_link= is an empty list; give one link (a chain) or several (a tree)"
        )
    bad = [t for t in tips if not isinstance(t, str) or not t]
    if bad:
        raise CalibrationError(f"{label}: tip_link= {bad[0]!r} is not a link name")
    twice = sorted({t for t in tips if tips.count(t) > 1})
    if twice:
        raise CalibrationError(f"{label}: tip_link= names {twice[0]!r} twice; give each tip once")
    return tips


@dataclass
class _State:
    """What the walk down a branch carries to a link: the actuated joint above it (-1: the
    base), the fixed joints since (their product) and the mimic joints since."""

    parent: int
    pending: np.ndarray
    passive: list


def read_tree(text: str, label: str, base_link: str | None, tips: list[str]):
    """The `Robot` of the tree from `base_link` to the links `tips` in URDF `text`
    (module doc)."""
    from .robot import Robot

    root, joints = parse(text, label)
    links = [el.get("name") for el in root.findall("link")]
    on: set[str] = set()
    for tip in tips:
        path, base_link, _ = chain_path(joints, base_link, tip, label, links)
        on.update(j.name for j in path)
    order = _depth_first([j for j in joints if j.name in on], base_link)
    actuated = [j.name for j in order if j.kind in MOVABLE and not j.mimic]
    out, parents, where = [], [], {}  # where: (joint, mimic) name -> the joint it went to
    states = {base_link: _State(-1, np.eye(4), [])}
    for j in order:
        s = states[j.parent]
        if j.kind == "fixed":
            states[j.child] = _State(s.parent, s.pending @ j.T, s.passive)
            continue
        if j.kind not in MOVABLE:
            raise CalibrationError(
                f"{label}, joint {j.name!r}: type {j.kind!r} is not supported in a robot to "
                "calibrate (revolute, continuous, prismatic, fixed)"
            )
        # the file's own numbers when no fixed joint folds in, as the serial reader keeps
        same = np.array_equal(s.pending, np.eye(4))
        xyz, rpy = (j.xyz, j.rpy) if same else split(s.pending @ j.T)
        if j.mimic:
            states[j.child] = _State(
                s.parent, np.eye(4), [*s.passive, _passive(j, xyz, rpy, actuated, label)]
            )
            continue
        for p in s.passive:
            if p.name in where:
                raise CalibrationError(
                    f"{label}: mimic joint {p.name!r} lies above a branch point (before both "
                    f"{where[p.name]!r} and {j.name!r}); casecal walks a mimic joint in one "
                    "branch only: make it the child of an actuated joint on one branch, or "
                    "leave the tips below it out"
                )
            where[p.name] = j.name
        kind, passive = MOVABLE[j.kind], tuple(s.passive)
        out.append(UrdfJoint(j.name, kind, j.axis, xyz, rpy, 0.0, j.limits, passive))
        parents.append(s.parent)
        states[j.child] = _State(len(out) - 1, np.eye(4), [])
    frames = [_tip(tip, states[tip], label, base_link) for tip in tips]
    inertials = body_inertials(root, joints, base_link, [j.name for j in out], label)
    return Robot(
        inertials=inertials,
        name=root.get("name") or _stem(label),
        joints=tuple(out),
        convention="urdf",
        parents=tuple(parents),
        tip_frames=tuple(frames),
        full_name=f"{root.get('name') or ''} ({base_link} to {', '.join(tips)})".strip(),
        source=(label,),
        urdf=UrdfSource(text, base_link, tuple(tips)),
    )


def body_inertials(root, joints, base_link: str, actuated: list[str], label: str) -> tuple:
    """Per actuated joint `actuated` (names, the robot's order) of a chain or tree, the
    mass (kg) and centre of mass (m, in the frame it moves) of everything it carries
    rigidly: its child link, the links after it through fixed joints, and the links of
    branches no measured tip lies beyond (a head, the other arm, a gripper after the
    tool frame), taken at their joints' zero; () when no link has a mass. Links moved by
    a mimic joint count nowhere (their motion is not the actuated joint's)."""
    from .urdf import _combined, _link_inertials

    masses = _link_inertials(root, label)
    if not masses:
        return ()
    index = {name: k for k, name in enumerate(actuated)}
    parts: list[list] = [[] for _ in actuated]
    owner = {base_link: None}  # link -> (joint index, its frame in that joint's moved frame)
    for j in _depth_first(joints, base_link):
        above = owner.get(j.parent)
        if j.name in index:
            owner[j.child] = (index[j.name], np.eye(4))
        elif above is None or j.mimic:
            owner[j.child] = None  # on the base, or moved by a mimic joint
        else:  # a fixed joint, or a joint off the tree at its zero
            owner[j.child] = (above[0], above[1] @ j.T)
        if owner[j.child] is not None and j.child in masses:
            k, T = owner[j.child]
            mass, com = masses[j.child]
            parts[k].append((mass, T[:3, :3] @ com + T[:3, 3]))
    inertials = tuple(_combined(p) if p else None for p in parts)
    return inertials if any(x is not None for x in inertials) else ()


def _stem(label: str) -> str:
    return Path(label).stem


def _tip(name: str, s: _State, label: str, base_link: str) -> Tip:
    if s.parent < 0:
        raise CalibrationError(
            f"{label}: no movable joint between {base_link!r} and tip {name!r}: nothing moves "
            "it, so it tells nothing about the robot; leave it out of tip_link="
        )
    if s.passive:
        raise CalibrationError(
            f"{label}: mimic joint {s.passive[0].name!r} comes after the last actuated joint "
            f"before tip {name!r}; end that branch before it (tip_link=)"
        )
    xyz, rpy = split(s.pending)
    return Tip(name, s.parent, xyz, rpy)


def _depth_first(joints: list, base_link: str) -> list:
    """`joints` (a tree below `base_link`) in depth-first order, children in the given
    order; iterative, so that a long chain costs no recursion."""
    below: dict[str, list] = {}
    for j in joints:
        below.setdefault(j.parent, []).append(j)
    order, pending = [], [iter(below.get(base_link, ()))]
    while pending:
        j = next(pending[-1], None)
        if j is None:
            pending.pop()
            continue
        order.append(j)
        pending.append(iter(below.get(j.child, ())))
    return order


# --- out: the URDF text with the calibrated numbers ------------------------------------


def _origins(robot) -> tuple[dict[str, np.ndarray], dict[str, list], list[str]]:
    """What `tree_urdf` writes: each movable joint's origin in its file's frames (4 × 4,
    offset folded in), the fixed joints that take the tips' frames (name → 4 × 4), and the
    tips whose frame has no fixed joint to go into (a tip that is a movable joint's child).

    A tip's frame goes into the last fixed joint before it, the fixed joints before that
    kept; the tips nearest the base first, so that a tip below another sees the other's
    joint as written, and the movable joints' origins are taken against the fixed joints
    as written: a tip link with joints below it moves nothing.
    """
    from .urdf_out import _rotation_about

    source = robot.urdf
    _, joints = parse(source.text, "URDF")
    paths = {tip: chain_path(joints, source.base_link, tip, "URDF")[0] for tip in robot.tips}
    fixed = {j.name: j.T for path in paths.values() for j in path if j.kind == "fixed"}
    movable = {j.name: j for j in robot.joints}
    movable.update({m.name: m for j in robot.joints for m in j.passive})
    written: dict[str, np.ndarray] = {}
    lost = []
    for tip in sorted(robot.tips, key=lambda t: len(paths[t])):
        after = []  # the fixed joints after the last movable one on the way to the tip
        for j in paths[tip]:
            after = [] if j.name in movable else [*after, j]
        if not after:
            lost.append(tip)
            continue
        before = np.eye(4)
        for j in after[:-1]:
            before = before @ fixed[j.name]
        frame = robot.tip_frames[robot.tips.index(tip)].matrix()
        fixed[after[-1].name] = written[after[-1].name] = np.linalg.inv(before) @ frame
    origins = {}
    for path in paths.values():
        pending = np.eye(4)
        for j in path:
            if j.name not in movable:
                pending = pending @ fixed[j.name]
                continue
            cj = movable[j.name]
            # a mimic joint's offset is its own (in <mimic>), not a calibrated zero offset
            turn = 0.0 if isinstance(cj, PassiveJoint) else cj.offset
            T = transform(cj.xyz, cj.rpy) @ _rotation_about(cj.axis, turn)
            origins[j.name] = np.linalg.inv(pending) @ T
            pending = np.eye(4)
    return origins, written, lost


def tree_urdf(robot) -> tuple[str, list[str]]:
    """The URDF text of tree `robot` (read from a URDF) with its calibrated numbers, and
    notes on what the file cannot hold (`casecal.model.urdf_out.calibrated_urdf`)."""
    from .urdf_out import _set_origin, offset_note

    if robot.urdf is None:
        raise CalibrationError(
            f"robot {robot.name!r} is a tree without the URDF it came from, and casecal "
            "writes a tree only into its own URDF text; save it as .toml, or load the tree "
            "from its URDF (tip_link= its tips) and calibrate that"
        )
    origins, written, _ = _origins(robot)
    text = robot.urdf.text
    for name, T in {**origins, **written}.items():
        text = _set_origin(text, name, *split(T))
    notes = offset_note(robot, "a URDF")
    if not np.allclose(transform(robot.base.xyz, robot.base.rpy), np.eye(4), rtol=0, atol=1e-15):
        notes.append(
            "the base frame (instrument to the base link) is not part of the robot and is "
            "not written; save the robot as .toml to keep it"
        )
    return text, notes


def tree_contract(robot, label: str):
    """What a URDF of tree `robot` holds (`casecal.model.urdf_out.urdf_contract`): read
    back with the same base link and tips, compared in the base link's frame; a tip that
    is a movable joint's child has no fixed joint to hold its frame."""
    import dataclasses

    from .export_check import Contract
    from .robot import Frame
    from .urdf import read_urdf

    source = robot.urdf
    reference = dataclasses.replace(robot, base=Frame(), auto_beta=False)
    held, reason = reference, ""
    lost = _origins(robot)[2] if source is not None else []
    if lost:
        held = dataclasses.replace(
            held,
            tip_frames=tuple(
                Tip(t.name, t.parent) if t.name in lost else t for t in held.tip_frames
            ),
            auto_beta=False,
        )
        reason = (
            f"the frame{'s' if len(lost) > 1 else ''} of tip{'s' if len(lost) > 1 else ''} "
            f"{', '.join(map(repr, lost))} {'are' if len(lost) > 1 else 'is'} not written: "
            "the tip link is a movable joint's child, and a URDF has no fixed joint there to "
            "hold it; add a fixed joint to a marker link in the URDF and load it with "
            "tip_link= that link, or save as .toml"
        )

    def read(text: str):
        return read_urdf(text, label, source.base_link, list(source.tip_link))

    return Contract("a URDF", reference, held, read, tool_reason=reason)


# --- robot files (TOML) ----------------------------------------------------------------


def toml_parents(rows: list[dict], label: str, number) -> tuple[list[dict], tuple[int, ...]]:
    """The ``[[joints]]`` rows of a tree's robot file without their ``parent`` keys, and the
    parents (0-based, -1: the base) they gave: ``parent = 0`` for the base, ``k`` for joint
    k (1-based, as a mimic joint's ``master``)."""
    plain, parents = [], []
    for i, row in enumerate(rows, start=1):
        if "parent" not in row:
            raise CalibrationError(
                f"{label}: joints[{i}] of a tree (a file with [[tips]]) needs parent = 0 (the "
                "base) or the number of the joint it hangs from (1-based)"
            )
        value = number(row["parent"], label, f"joints[{i}].parent")
        if value != int(value) or not 0 <= value < i:
            raise CalibrationError(
                f"{label}: joints[{i}].parent = {row['parent']!r}; give 0 (the base) or the "
                f"number of a joint before it (1 … {i - 1})"
            )
        parents.append(int(value) - 1)
        plain.append({k: v for k, v in row.items() if k != "parent"})
    return plain, tuple(parents)


def toml_tips(data: dict, n_joints: int, length: float, angle: float, label: str, number):
    """The ``[[tips]]`` tables of a tree's robot file as `Tip` (SI)."""
    rows = data["tips"]
    if not isinstance(rows, list) or not rows or not all(isinstance(r, dict) for r in rows):
        raise CalibrationError(
            f"{label}: tips must be [[tips]] tables, each with name, parent (the joint it "
            "rides on, 1-based), xyz and rpy"
        )
    tips = []
    for k, row in enumerate(rows, start=1):
        where = f"tips[{k}]"
        unknown = sorted(set(row) - {"name", "parent", "xyz", "rpy"})
        if unknown:
            raise CalibrationError(f"{label}: {where} has unknown key {unknown[0]!r}")
        if not isinstance(row.get("name"), str) or "parent" not in row:
            raise CalibrationError(f'{label}: {where} needs name = "..." and parent = <joint>')
        parent = number(row["parent"], label, f"{where}.parent")
        if parent != int(parent) or not 1 <= parent <= n_joints:
            raise CalibrationError(
                f"{label}: {where}.parent = {row['parent']!r}; give the number of the joint "
                f"the tip rides on (1 … {n_joints})"
            )

        def triple(key, scale, row=row, where=where):
            value = row.get(key, [0, 0, 0])
            if not isinstance(value, list) or len(value) != 3:
                raise CalibrationError(f"{label}: {where}.{key} must be [x, y, z]")
            return tuple(number(v, label, f"{where}.{key}") * scale for v in value)

        tips.append(Tip(row["name"], int(parent) - 1, triple("xyz", length), triple("rpy", angle)))
    return tuple(tips)


def toml_lines(robot, i: int) -> list[str]:
    """The ``parent`` line of joint `i` (0-based) of tree `robot`'s robot file."""
    return [f"parent = {robot.parents[i] + 1}"]


def toml_tip_lines(robot, quote) -> list[str]:
    """The ``[[tips]]`` tables of tree `robot` (m, rad) that `toml_tips` reads back."""

    def three(values):
        return "[" + ", ".join(repr(float(v)) for v in values) + "]"

    lines = []
    for t in robot.tip_frames:
        lines += [
            "",
            "[[tips]]",
            f"name = {quote(t.name)}",
            f"parent = {t.parent + 1}",
            f"xyz = {three(t.xyz)}",
            f"rpy = {three(t.rpy)}",
        ]
    return lines
