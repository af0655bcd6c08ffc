"""Robots from URDF files: the serial chain from a base link to a tip link.

Each movable joint (revolute, continuous, prismatic, any axis) keeps its origin as six
parameters in the file's own frames and, when revolute, a zero offset of its angle (names
in `casecal.model.parameters`). Fixed joints fold into their neighbours: those before a
movable joint into its origin, those after the last one into the tool frame. The original
text is kept on the robot, so that `casecal.model.urdf_out` can write the calibrated
numbers back into it with everything else unchanged.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CalibrationError
from .frames import matrix_from_rpy, rpy_from_matrix
from .urdf_tree import MOVABLE, chain_path, check_tree


@dataclass(frozen=True)
class UrdfJoint:
    """One movable joint of a URDF chain, SI.

    Attributes
    ----------
    name : str
        The joint's name in the file.
    type : {"R", "P"}
    axis : (float, float, float)
        Unit axis in the joint's frame.
    xyz, rpy : (float, float, float)
        Origin (m, rad: roll, pitch, yaw), with the fixed joints before it folded in.
    offset : float
        Zero offset of the joint angle, rad (0 for prismatic joints).
    limits : (float, float) or None
        rad or m; None for a continuous joint.
    """

    name: str
    type: str
    axis: tuple[float, float, float]
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    offset: float = 0.0
    limits: tuple[float, float] | None = None
    passive: tuple = ()


@dataclass(frozen=True)
class PassiveJoint:
    """A mimic joint on the chain, walked just before the `UrdfJoint` that holds it.

    Its variable is ``multiplier · q[master] + offset`` (master: 0-based index of an
    actuated joint); its origin (xyz m, rpy rad) is six parameters ``{name}.x`` … ``.yaw``.
    """

    name: str
    type: str
    axis: tuple[float, float, float]
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    master: int
    multiplier: float = 1.0
    offset: float = 0.0

    @property
    def shape(self) -> tuple:
        """What the symbolic graph depends on."""
        return (self.name, self.type, self.axis, self.master, self.multiplier, self.offset)


def check_joints(robot: str, joints) -> None:
    """Raise CalibrationError unless `joints` are valid `UrdfJoint` rows."""
    names = set()
    for j in joints:
        if not isinstance(j, UrdfJoint) or j.type not in ("R", "P"):
            raise CalibrationError(f"robot {robot!r}: a URDF robot's joints must be URDF joints")
        values = [*j.xyz, *j.rpy, *j.axis, j.offset]
        if not all(math.isfinite(v) for v in values):
            raise CalibrationError(f"robot {robot!r}, joint {j.name!r}: a non-finite number")
        if abs(np.linalg.norm(j.axis) - 1) > 1e-9:
            raise CalibrationError(f"robot {robot!r}, joint {j.name!r}: axis is not a unit vector")
        for p in j.passive:
            if not isinstance(p, PassiveJoint) or not 0 <= p.master < len(joints):
                raise CalibrationError(f"robot {robot!r}: mimic joint {p.name!r} has no master")
        for name in (j.name, *(p.name for p in j.passive)):
            if name in names:
                raise CalibrationError(f"robot {robot!r}: joint {name!r} appears twice")
            names.add(name)


def transform(xyz, rpy) -> np.ndarray:
    """``Trans(xyz) · Rz(yaw) Ry(pitch) Rx(roll)``, shape (4, 4)."""
    T = np.eye(4)
    T[:3, :3] = matrix_from_rpy(rpy)
    T[:3, 3] = xyz
    return T


def split(T: np.ndarray) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """xyz (m) and roll, pitch, yaw (rad) of a 4 × 4 transform."""
    return tuple(float(v) for v in T[:3, 3]), rpy_from_matrix(T[:3, :3])


@dataclass(frozen=True)
class UrdfSource:
    """The URDF text a robot was read from, and the chain's ends in it (a tree's tips: a
    tuple of links)."""

    text: str
    base_link: str
    tip_link: str | tuple[str, ...]

    def __repr__(self) -> str:
        return f"UrdfSource({self.base_link!r} to {self.tip_link!r}, {len(self.text)} characters)"


@dataclass(frozen=True)
class _Joint:
    """A `<joint>` element as read."""

    name: str
    kind: str
    parent: str
    child: str
    T: np.ndarray
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float]
    axis: tuple[float, float, float]
    limits: tuple[float, float] | None
    mimic: tuple[str, float, float] | None  # (master joint, multiplier, offset)


def _numbers(text: str | None, n: int, what: str, label: str) -> tuple[float, ...]:
    if text is None:
        return (0.0,) * n
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError:
        wanted = "a number" if n == 1 else f"{n} numbers"
        raise CalibrationError(f"{label}: {what} {text!r} is not {wanted}") from None
    if len(values) != n or not all(math.isfinite(v) for v in values):
        wanted = "a finite number" if n == 1 else f"{n} finite numbers"
        raise CalibrationError(f"{label}: {what} {text!r} is not {wanted}")
    return values


def _read_joint(el: ET.Element, label: str) -> _Joint:
    name = el.get("name")
    parent, child = el.find("parent"), el.find("child")
    if not name:
        below = "" if child is None else f" (child link {child.get('link')!r})"
        raise CalibrationError(f'{label}: a <joint>{below} has no name=; give it name="..."')
    where = f"{label}, joint {name!r}"
    kind = el.get("type", "")
    if parent is None or child is None:
        raise CalibrationError(f"{where}: needs a <parent link=...> and a <child link=...>")
    origin = el.find("origin")
    xyz = _numbers(None if origin is None else origin.get("xyz"), 3, "origin xyz", where)
    rpy = _numbers(None if origin is None else origin.get("rpy"), 3, "origin rpy", where)
    axis = _axis(el.find("axis"), kind, where)
    return _Joint(
        name,
        kind,
        parent.get("link", ""),
        child.get("link", ""),
        transform(xyz, rpy),
        xyz,
        rpy,
        axis,
        _limits(el.find("limit"), kind, where),
        _mimic(el.find("mimic"), where),
    )


def _axis(el: ET.Element | None, kind: str, where: str) -> tuple[float, float, float]:
    """The unit axis of a joint: (1, 0, 0) without <axis>, as the URDF spec says."""
    if el is None:
        return (1.0, 0.0, 0.0)
    if kind not in MOVABLE:  # a fixed joint's axis moves nothing
        return (1.0, 0.0, 0.0)
    if el.get("xyz") is None:
        raise CalibrationError(f'{where}: <axis> has no xyz=; write e.g. <axis xyz="0 0 1"/>')
    axis = np.array(_numbers(el.get("xyz"), 3, "axis xyz", where))
    norm = float(np.linalg.norm(axis))
    if not norm > 1e-12:
        raise CalibrationError(
            f'{where}: axis xyz="{el.get("xyz")}" is zero; give the direction the joint '
            'moves along, e.g. <axis xyz="0 0 1"/>'
        )
    return tuple(float(v) for v in axis / norm)


def _limits(el: ET.Element | None, kind: str, where: str) -> tuple[float, float] | None:
    """A revolute or prismatic joint's (lower, upper), rad or m; None for other kinds."""
    if kind not in ("revolute", "prismatic"):
        return None
    if el is None or el.get("lower") is None or el.get("upper") is None:
        raise CalibrationError(f"{where}: a {kind} joint needs <limit lower=... upper=...>")
    lower = _numbers(el.get("lower"), 1, "lower limit", where)[0]
    upper = _numbers(el.get("upper"), 1, "upper limit", where)[0]
    if lower > upper:  # lower == upper is a joint held still, which URDF allows
        scale, unit = (180 / math.pi, "deg") if kind == "revolute" else (1e3, "mm")
        raise CalibrationError(
            f'{where}: <limit lower="{el.get("lower")}" upper="{el.get("upper")}"> is '
            f"{lower * scale:.6g} {unit} to {upper * scale:.6g} {unit}: lower must be below "
            "upper; swap them"
        )
    return lower, upper


def _mimic(el: ET.Element | None, where: str) -> tuple[str, float, float] | None:
    if el is None:
        return None
    multiplier = _numbers(el.get("multiplier", "1"), 1, "mimic multiplier", where)[0]
    offset = _numbers(el.get("offset", "0"), 1, "mimic offset", where)[0]
    return el.get("joint", ""), multiplier, offset


def parse(text: str, label: str) -> tuple[ET.Element, list[_Joint]]:
    """The root element and the joints of URDF `text`, checked to make a tree."""
    if not text.strip():
        raise CalibrationError(
            f"{label}: the file is empty; a URDF is an XML file with a <robot> element"
        )
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise CalibrationError(f"{label}: not valid XML ({exc})") from None
    for el in root.iter():  # a default namespace (xmlns="...") names every tag {ns}tag
        if isinstance(el.tag, str) and el.tag.startswith("{"):
            el.tag = el.tag.split("}", 1)[1]
    if root.tag != "robot":
        raise CalibrationError(f"{label}: the root element is <{root.tag}>, not <robot>")
    # every <joint> of the robot; elsewhere (a <transmission>'s) only those with a parent
    top = set(root.findall("joint"))
    joints = [
        _read_joint(el, label)
        for el in root.iter("joint")
        if el in top or el.find("parent") is not None
    ]
    check_tree(root, joints, label)
    return root, joints


def read_urdf(text: str, label: str = "URDF", base_link: str | None = None, tip_link=None):
    """The `Robot` of the chain from `base_link` to `tip_link` in URDF `text`.

    Defaults: the root link, and the end of the one chain with the most movable joints
    (``tool0`` among equals). Fixed joints fold into the next movable joint's origin, those
    after the last into the tool frame.

    `tip_link` a list or tuple of links: with one, the chain to it; with several, the tree
    of the paths to them (`casecal.model.tree`), each a measured tip.
    """
    from .robot import Frame, Robot

    if isinstance(tip_link, list | tuple):
        from .tree import read_tree, tip_links

        tips = tip_links(tip_link, label)
        if len(tips) > 1:
            return read_tree(text, label, base_link, tips)
        tip_link = tips[0]

    root, joints = parse(text, label)
    links = [el.get("name") for el in root.findall("link")]
    path, base_link, tip_link = chain_path(joints, base_link, tip_link, label, links)
    out, pending = [], np.eye(4)

    actuated = [j.name for j in path if j.kind in MOVABLE and not j.mimic]
    passive: list[PassiveJoint] = []
    for j in path:
        if j.kind == "fixed":
            pending = pending @ j.T
            continue
        if j.kind not in MOVABLE:
            raise CalibrationError(
                f"{label}, joint {j.name!r}: type {j.kind!r} is not supported in a serial "
                "chain (revolute, continuous, prismatic, fixed)"
            )
        # the file's own numbers when no fixed joint folds in: a round trip through the
        # matrix would cost digits
        xyz, rpy = (j.xyz, j.rpy) if np.array_equal(pending, np.eye(4)) else split(pending @ j.T)
        pending = np.eye(4)
        if j.mimic:
            passive.append(_passive(j, xyz, rpy, actuated, label))
            continue
        out.append(
            UrdfJoint(j.name, MOVABLE[j.kind], j.axis, xyz, rpy, 0.0, j.limits, tuple(passive))
        )
        passive = []
    if not out:
        raise CalibrationError(f"{label}: no movable joint between {base_link!r} and {tip_link!r}")
    if passive:
        raise CalibrationError(
            f"{label}: mimic joint {passive[0].name!r} comes after the last actuated joint; "
            "end the chain before it with tip_link= (--tip-link on the command line)"
        )
    tool_xyz, tool_rpy = split(pending)
    from .tree import body_inertials

    return Robot(
        inertials=body_inertials(root, joints, base_link, actuated, label),
        name=root.get("name") or Path(label).stem,
        joints=tuple(out),
        convention="urdf",
        tool=Frame(tool_xyz, tool_rpy),
        full_name=f"{root.get('name') or ''} ({base_link} to {tip_link})".strip(),
        source=(label,),
        urdf=UrdfSource(text, base_link, tip_link),
    )


def _passive(j, xyz, rpy, actuated: list[str], label: str) -> PassiveJoint:
    master, multiplier, offset = j.mimic
    if master not in actuated:
        raise CalibrationError(
            f"{label}, joint {j.name!r}: it mimics {master!r}, which is not an actuated joint "
            "of this chain"
        )
    return PassiveJoint(
        j.name, MOVABLE[j.kind], j.axis, xyz, rpy, actuated.index(master), multiplier, offset
    )


def _link_inertials(root: ET.Element, label: str) -> dict[str, tuple[float, np.ndarray]]:
    """Each link's mass (kg) and centre of mass (m, link frame) from its <inertial>."""
    out = {}
    for link in root.iter("link"):
        inertial = link.find("inertial")
        if inertial is None or inertial.find("mass") is None:
            continue
        where = f"{label}, link {link.get('name')!r}"
        mass = _numbers(inertial.find("mass").get("value"), 1, "mass", where)[0]
        origin = inertial.find("origin")
        com = _numbers(None if origin is None else origin.get("xyz"), 3, "inertial xyz", where)
        if mass > 0:
            out[link.get("name", "")] = (mass, np.array(com))
    return out


def _combined(parts) -> tuple[float, tuple[float, float, float]] | None:
    """One body's mass and centre of mass from the links riding on it, or None."""
    total = sum(m for m, _ in parts)
    if total <= 0:
        return None
    com = parts[0][1] if len(parts) == 1 else sum(m * c for m, c in parts) / total
    return float(total), tuple(float(v) for v in com)


def load_urdf(
    path: Path,
    base_link: str | None = None,
    tip_link=None,
    packages: dict[str, str] | None = None,
):
    """Read a ``.urdf`` file, or expand a ``.xacro`` one (the ``urdf`` extra).

    `tip_link`: a link, or a list of links (`read_urdf`).

    `packages` maps ROS package names to folders for ``$(find pkg)`` and
    ``package://`` in a xacro file; folders above the file are found by themselves.
    """
    from ..textio import read_text

    if path.suffix == ".xacro" or path.name.endswith(".urdf.xacro"):
        from .urdf_xacro import expand_xacro

        text = expand_xacro(path, packages or {})
    else:
        text = read_text(path, "URDF file")
    return read_urdf(text, str(path), base_link, tip_link)
