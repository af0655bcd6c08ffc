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

MOVABLE = {"revolute": "R", "continuous": "R", "prismatic": "P"}


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
    """The URDF text a robot was read from, and the chain's ends in it."""

    text: str
    base_link: str
    tip_link: str

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
        raise CalibrationError(f"{label}: {what} {text!r} is not {n} numbers") from None
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise CalibrationError(f"{label}: {what} {text!r} is not {n} finite numbers")
    return values


def _read_joint(el: ET.Element, label: str) -> _Joint:
    name = el.get("name") or "?"
    where = f"{label}, joint {name!r}"
    kind = el.get("type", "")
    parent, child = el.find("parent"), el.find("child")
    if parent is None or child is None:
        raise CalibrationError(f"{where}: needs a <parent link=...> and a <child link=...>")
    origin = el.find("origin")
    xyz = _numbers(None if origin is None else origin.get("xyz"), 3, "origin xyz", where)
    rpy = _numbers(None if origin is None else origin.get("rpy"), 3, "origin rpy", where)
    axis_el = el.find("axis")
    axis = np.array(_numbers(None if axis_el is None else axis_el.get("xyz"), 3, "axis", where))
    if axis_el is None:
        axis = np.array([1.0, 0.0, 0.0])  # the URDF default
    if kind in MOVABLE and np.linalg.norm(axis) == 0:
        raise CalibrationError(f"{where}: axis is zero")
    limits = None
    limit = el.find("limit")
    if kind in ("revolute", "prismatic"):
        if limit is None or limit.get("lower") is None or limit.get("upper") is None:
            raise CalibrationError(f"{where}: a {kind} joint needs <limit lower=... upper=...>")
        limits = (
            _numbers(limit.get("lower"), 1, "lower limit", where)[0],
            _numbers(limit.get("upper"), 1, "upper limit", where)[0],
        )
    return _Joint(
        name,
        kind,
        parent.get("link", ""),
        child.get("link", ""),
        transform(xyz, rpy),
        xyz,
        rpy,
        tuple(float(v) for v in axis / max(np.linalg.norm(axis), 1e-300)),
        limits,
        _mimic(el.find("mimic"), where),
    )


def _mimic(el: ET.Element | None, where: str) -> tuple[str, float, float] | None:
    if el is None:
        return None
    multiplier = _numbers(el.get("multiplier", "1"), 1, "mimic multiplier", where)[0]
    offset = _numbers(el.get("offset", "0"), 1, "mimic offset", where)[0]
    return el.get("joint", ""), multiplier, offset


def chain_path(joints: list[_Joint], base_link: str | None, tip_link: str | None, label: str):
    """The joints from `base_link` to `tip_link` (defaults in `read_urdf`), in order."""
    by_child = {j.child: j for j in joints}
    children = {j.parent for j in joints} | {j.child for j in joints}
    roots = sorted({j.parent for j in joints} - set(by_child))
    if base_link is None:
        if len(roots) != 1:
            raise CalibrationError(
                f"{label}: several root links ({', '.join(roots)}); give base_link= one of "
                "them (--base-link on the command line)"
            )
        base_link = roots[0]
    if base_link not in children:
        raise CalibrationError(
            f"{label}: no link {base_link!r}; links: {', '.join(sorted(children))}"
        )

    def path_to(link):
        path = []
        while link != base_link:
            if link not in by_child:
                return None
            path.append(by_child[link])
            link = path[-1].parent
        return path[::-1]

    if tip_link is None:
        leaves = sorted({j.child for j in joints} - {j.parent for j in joints})
        paths = {leaf: path_to(leaf) for leaf in leaves}
        paths = {k: v for k, v in paths.items() if v is not None}
        moving = {k: tuple(j.name for j in v if j.kind in MOVABLE) for k, v in paths.items()}
        most = max((len(m) for m in moving.values()), default=0)
        tips = [k for k, m in moving.items() if len(m) == most and most > 0]
        if len({moving[k] for k in tips}) == 1 and "tool0" in tips:
            tips = ["tool0"]
        if len(tips) != 1:
            raise CalibrationError(
                f"{label}: more than one chain ends here; give tip_link= one of "
                f"{', '.join(tips) or '(no movable chain found)'} (--tip-link on the command line)"
            )
        tip_link = tips[0]
    path = path_to(tip_link)
    if path is None:
        raise CalibrationError(f"{label}: link {tip_link!r} is not below {base_link!r}")
    return path, base_link, tip_link


def parse(text: str, label: str) -> tuple[ET.Element, list[_Joint]]:
    """The root element and the joints of URDF `text`."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise CalibrationError(f"{label}: not valid XML ({exc})") from None
    for el in root.iter():  # a default namespace (xmlns="...") names every tag {ns}tag
        if isinstance(el.tag, str) and el.tag.startswith("{"):
            el.tag = el.tag.split("}", 1)[1]
    if root.tag != "robot":
        raise CalibrationError(f"{label}: the root element is <{root.tag}>, not <robot>")
    return root, [
        _read_joint(el, label) for el in root.iter("joint") if el.find("parent") is not None
    ]


def read_urdf(
    text: str, label: str = "URDF", base_link: str | None = None, tip_link: str | None = None
):
    """The `Robot` of the chain from `base_link` to `tip_link` in URDF `text`.

    Defaults: the root link, and the end of the one chain with the most movable joints
    (``tool0`` among equals). Fixed joints fold into the next movable joint's origin, those
    after the last into the tool frame.
    """
    from .robot import Frame, Robot

    root, joints = parse(text, label)
    path, base_link, tip_link = chain_path(joints, base_link, tip_link, label)
    masses = _link_inertials(root, label)
    out, pending, bodies, since = [], np.eye(4), [], np.eye(4)

    actuated = [j.name for j in path if j.kind in MOVABLE and not j.mimic]
    passive: list[PassiveJoint] = []

    def carry(link: str) -> None:  # the link's mass, in the frame of the body it rides on
        if bodies and bodies[-1] is not None and link in masses:
            mass, com = masses[link]
            bodies[-1].append((mass, since[:3, :3] @ com + since[:3, 3]))

    for j in path:
        if j.kind == "fixed":
            pending, since = pending @ j.T, since @ j.T
            carry(j.child)
            continue
        if j.kind not in MOVABLE:
            raise CalibrationError(
                f"{label}, joint {j.name!r}: type {j.kind!r} is not supported in a serial "
                "chain (revolute, continuous, prismatic, fixed)"
            )
        # the file's own numbers when no fixed joint folds in: a round trip through the
        # matrix would cost digits
        xyz, rpy = (j.xyz, j.rpy) if np.array_equal(pending, np.eye(4)) else split(pending @ j.T)
        pending, since = np.eye(4), np.eye(4)
        if j.mimic:
            passive.append(_passive(j, xyz, rpy, actuated, label))
            bodies.append(None)  # what a mimic joint moves is left out of gravity torques
            continue
        out.append(
            UrdfJoint(j.name, MOVABLE[j.kind], j.axis, xyz, rpy, 0.0, j.limits, tuple(passive))
        )
        passive = []
        bodies.append([])
        carry(j.child)
    if not out:
        raise CalibrationError(f"{label}: no movable joint between {base_link!r} and {tip_link!r}")
    if passive:
        raise CalibrationError(
            f"{label}: mimic joint {passive[0].name!r} comes after the last actuated joint; "
            "end the chain before it with tip_link= (--tip-link on the command line)"
        )
    tool_xyz, tool_rpy = split(pending)
    inertials = tuple(_combined(parts) for parts in bodies if parts is not None)
    return Robot(
        inertials=inertials if any(x is not None for x in inertials) else (),
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
    tip_link: str | None = None,
    packages: dict[str, str] | None = None,
):
    """Read a ``.urdf`` file, or expand a ``.xacro`` one (the ``urdf`` extra).

    `packages` maps ROS package names to folders for ``$(find pkg)`` and
    ``package://`` in a xacro file; folders above the file are found by themselves.
    """
    from ..textio import read_text

    if path.suffix == ".xacro" or path.name.endswith(".urdf.xacro"):
        text = _expand_xacro(path, packages or {})
    else:
        text = read_text(path, "URDF file")
    return read_urdf(text, str(path), base_link, tip_link)


def _expand_xacro(path: Path, packages: dict[str, str]) -> str:
    """The URDF text of a xacro file, by xacrodoc (which resolves ROS packages without a
    ROS install), else by the xacro package."""
    if not path.is_file():
        raise CalibrationError(f"{path}: no such file")
    try:
        from xacrodoc import XacroDoc
        from xacrodoc import packages as known

        def expand() -> str:
            known.walk_up_from(str(path))
            known.update_package_cache(dict(packages))
            return XacroDoc.from_file(str(path)).to_urdf_string()

    except ImportError:
        try:
            import xacro
        except ImportError:
            raise CalibrationError(
                f"{path}: a .xacro file needs the urdf extra: pip install 'casecal[urdf]'"
            ) from None

        def expand() -> str:
            return xacro.process_file(str(path)).toxml()

    try:
        return expand()
    except Exception as exc:  # xacro raises its own and many builtin types
        detail = " ".join(str(exc).split())
        raise CalibrationError(
            f"{path}: xacro could not expand it ({detail}); name the ROS packages it "
            "finds with packages={name: folder} (Python: load_robot), or run 'xacro FILE > "
            "robot.urdf' in its workspace and load the .urdf (the command line's way)"
        ) from None
