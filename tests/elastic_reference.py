"""An independent numpy reference for elastic kinematic trees read from URDF text.

Not a test module, and no casecal import: the URDF is parsed with xml.etree, the tree is
walked link by link, and the elastic model is written from its specification:

- rigid frames first (every deflection zero); for a joint i that moves a tip: a_i its
  world unit axis, p_i the world origin of its child link, B_i that link's world pose;
- M_i = Σ over every link below joint i (all branches, fixed joints and branches that no
  tip measures included) of (c_l − p_i) × (m_l g), c_l the link's world centre of mass;
- torsion: joint i turns by q_i + c_i (M_i · a_i);
- lateral: u_i the part perpendicular to a_i of the child frame's axis least aligned with
  the URDF axis vector (x on ties), v_i = a_i × u_i, and right after joint i's motion, in
  the child frame, Rot(R_B^T u_i, cu_i (M_i·u_i)) Rot(R_B^T v_i, cv_i (M_i·v_i)).

Joints that lead to no tip (branches off the tree) stay at zero. Prismatic joints slide
their child link along their axis (m) and carry no compliance.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

STANDARD_GRAVITY = 9.80665


def rot(axis, angle) -> np.ndarray:
    """Rotation by `angle` about unit-normalised `axis` (Rodrigues), 3 × 3."""
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)


def rpy_matrix(rpy) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    return rot((0, 0, 1), y) @ rot((0, 1, 0), p) @ rot((1, 0, 0), r)


def homogeneous(R=None, t=None) -> np.ndarray:
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if t is not None:
        T[:3, 3] = t
    return T


def _floats(text, default):
    return np.array([float(x) for x in text.split()]) if text else np.array(default, float)


@dataclass
class UJoint:
    name: str
    type: str
    parent: str
    child: str
    xyz: np.ndarray
    rpy: np.ndarray
    axis: np.ndarray

    @property
    def origin(self) -> np.ndarray:
        return homogeneous(rpy_matrix(self.rpy), self.xyz)


@dataclass
class Tree:
    """A URDF tree: links (name -> (mass, com) or None), joints by child link."""

    root: str
    links: dict
    joints: dict  # child link -> UJoint
    children: dict = field(default_factory=dict)  # link -> list of UJoint
    tips: tuple = ()
    moving: tuple = ()  # names of the revolute joints on a path to a tip

    def walk(self):
        """Links in depth-first order from the root."""
        stack, out = [self.root], []
        while stack:
            link = stack.pop()
            out.append(link)
            stack.extend(j.child for j in reversed(self.children.get(link, [])))
        return out

    def below(self, link) -> list:
        """`link` and every link under it."""
        stack, out = [link], []
        while stack:
            x = stack.pop()
            out.append(x)
            stack.extend(j.child for j in self.children.get(x, []))
        return out


def parse_urdf(text: str, tips) -> Tree:
    root_el = ET.fromstring(text)
    links = {}
    for el in root_el.findall("link"):
        inertial = el.find("inertial")
        if inertial is None:
            links[el.get("name")] = None
            continue
        mass = float(inertial.find("mass").get("value"))
        origin = inertial.find("origin")
        com = _floats(origin.get("xyz") if origin is not None else None, [0, 0, 0])
        links[el.get("name")] = (mass, com)
    joints, children = {}, {}
    for el in root_el.findall("joint"):
        origin = el.find("origin")
        axis = el.find("axis")
        j = UJoint(
            name=el.get("name"),
            type=el.get("type"),
            parent=el.find("parent").get("link"),
            child=el.find("child").get("link"),
            xyz=_floats(origin.get("xyz") if origin is not None else None, [0, 0, 0]),
            rpy=_floats(origin.get("rpy") if origin is not None else None, [0, 0, 0]),
            axis=_floats(axis.get("xyz") if axis is not None else None, [1, 0, 0]),
        )
        joints[j.child] = j
        children.setdefault(j.parent, []).append(j)
    roots = [name for name in links if name not in joints]
    assert len(roots) == 1, roots
    tree = Tree(roots[0], links, joints, children, tuple(tips))
    on_path = set()
    for tip in tips:
        link = tip
        while link in joints:
            j = joints[link]
            if j.type in ("revolute", "continuous", "prismatic"):
                on_path.add(j.name)
            link = j.parent
    tree.moving = tuple(
        joints[link].name for link in tree.walk() if link in joints and joints[link].name in on_path
    )
    return tree


def _frames(tree: Tree, angles: dict, after=None) -> dict:
    """World pose of every link; `angles` joint name -> angle (moving joints; others 0);
    `after` joint name -> 4 × 4 transform applied after the joint's motion."""
    T = {tree.root: np.eye(4)}
    for link in tree.walk():
        if link == tree.root:
            continue
        j = tree.joints[link]
        M = T[j.parent] @ j.origin
        if j.type in ("revolute", "continuous"):
            M = M @ homogeneous(rot(j.axis, angles.get(j.name, 0.0)))
            if after is not None and j.name in after:
                M = M @ after[j.name]
        elif j.type == "prismatic":
            M = M @ homogeneous(t=j.axis / np.linalg.norm(j.axis) * angles.get(j.name, 0.0))
        T[link] = M
    return T


def moments(tree: Tree, q: dict, gravity) -> dict:
    """Per moving joint: (a, p, B, M) on the rigid tree, world frame (module doc)."""
    T = _frames(tree, q)
    g = np.asarray(gravity, dtype=float)
    out = {}
    for name in tree.moving:
        j = next(x for x in tree.joints.values() if x.name == name)
        if j.type == "prismatic":
            continue
        B = T[j.child]
        a = B[:3, :3] @ (j.axis / np.linalg.norm(j.axis))
        p = B[:3, 3]
        M = np.zeros(3)
        for link in tree.below(j.child):
            if tree.links[link] is None:
                continue
            mass, com = tree.links[link]
            c = T[link][:3, :3] @ com + T[link][:3, 3]
            M += np.cross(c - p, mass * g)
        out[name] = (a, p, B, M)
    return out


def tip_positions(tree: Tree, q: dict, compliance=None, gravity=(0, 0, -STANDARD_GRAVITY)):
    """Tip positions (tips, 3) at joint angles `q` (name -> rad) with `compliance`
    (name -> (c, cu, cv), rad/(N·m); missing: 0)."""
    compliance = compliance or {}
    angles, after = dict(q), {}
    for name, (a, _p, B, M) in moments(tree, q, gravity).items():
        c, cu, cv = compliance.get(name, (0.0, 0.0, 0.0))
        angles[name] = q.get(name, 0.0) + c * (M @ a)
        j = next(x for x in tree.joints.values() if x.name == name)
        pick = int(np.argmin(np.abs(j.axis)))
        e = B[:3, pick]
        u = e - (e @ a) * a
        u /= np.linalg.norm(u)
        v = np.cross(a, u)
        R = B[:3, :3]
        after[name] = homogeneous(rot(R.T @ u, cu * (M @ u)) @ rot(R.T @ v, cv * (M @ v)))
    T = _frames(tree, angles, after)
    return np.array([T[tip][:3, 3] for tip in tree.tips])


def tip_positions_world(tree: Tree, q: dict, compliance=None, gravity=(0, 0, -STANDARD_GRAVITY)):
    """The same model as `tip_positions` written the world way: each joint's lateral
    turn D_i (about p_i, world axes u_i, v_i of the rigid tree) applied to everything it
    moves. Agrees with `tip_positions` at first order in the compliances only."""
    compliance = compliance or {}
    mom = moments(tree, q, gravity)
    angles = dict(q)
    for name, (a, _p, _B, M) in mom.items():
        angles[name] = q.get(name, 0.0) + compliance.get(name, (0, 0, 0))[0] * (M @ a)
    T = _frames(tree, angles)
    out = []
    for tip in tree.tips:
        x = T[tip][:3, 3].copy()
        # the joints above the tip, the deepest first: each turns what it carries
        link, chain = tip, []
        while link in tree.joints:
            j = tree.joints[link]
            if j.name in mom:
                chain.append(j)
            link = j.parent
        for j in chain:
            a, p, B, M = mom[j.name]
            _c, cu, cv = compliance.get(j.name, (0.0, 0.0, 0.0))
            e = B[:3, int(np.argmin(np.abs(j.axis)))]
            u = e - (e @ a) * a
            u /= np.linalg.norm(u)
            v = np.cross(a, u)
            D = rot(u, cu * (M @ u)) @ rot(v, cv * (M @ v))
            x = D @ (x - p) + p
        out.append(x)
    return np.array(out)


def _fmt(v):
    return " ".join(repr(float(x)) for x in v)


def add_inertials(text: str, rng, links=None) -> str:
    """URDF `text` with an <inertial> (0.5–5 kg, centre of mass within ±0.1 m) on every
    link (or on `links`) that has none."""
    root = ET.fromstring(text)
    for el in root.findall("link"):
        if el.find("inertial") is not None or (links is not None and el.get("name") not in links):
            continue
        inertial = ET.SubElement(el, "inertial")
        ET.SubElement(inertial, "origin", xyz=_fmt(rng.uniform(-0.1, 0.1, 3)), rpy="0 0 0")
        ET.SubElement(inertial, "mass", value=repr(float(rng.uniform(0.5, 5))))
        ET.SubElement(
            inertial, "inertia", ixx="0.01", ixy="0", ixz="0", iyy="0.01", iyz="0", izz="0.01"
        )
    return ET.tostring(root, encoding="unicode")


def random_axis(rng) -> np.ndarray:
    kind = rng.integers(0, 5)
    if kind < 3:
        v = np.zeros(3)
        v[kind] = rng.choice([-1.0, 1.0])
        return v
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def random_tree_urdf(rng, masses: bool = True):
    """A random URDF tree: (text, tips). 2–3 tips (fixed-joint markers on leaves), 8–20
    revolute/continuous joints leading to them, fixed joints in between, x/y/z and skew
    axes, and at least one branch that no tip measures, with mass, hanging below a
    moving joint (its revolute joints stay at zero)."""
    while True:
        n_tips = int(rng.integers(2, 4))
        links = ["base"]
        kids: dict = {"base": []}
        joints = []
        n = int(rng.integers(12, 26))
        for k in range(n):
            parent = links[-1] if rng.random() < 0.7 else links[int(rng.integers(0, len(links)))]
            child = f"l{k}"
            r = rng.random()
            jtype = "fixed" if r < 0.2 else ("continuous" if r < 0.3 else "revolute")
            joints.append((f"j{k}", jtype, parent, child))
            kids[parent].append(child)
            kids[child] = []
            links.append(child)
        leaves = [x for x in links if not kids[x]]
        if len(leaves) < n_tips + 1:
            continue
        order = rng.permutation(len(leaves))
        ends = [leaves[i] for i in order[:n_tips]]
        spare = [leaves[i] for i in order[n_tips:]]
        by_child = {c: (nm, t, p) for nm, t, p, c in joints}

        def up(link, by_child=by_child):
            out = []
            while link in by_child:
                out.append(link)
                link = by_child[link][2]
            return out

        on = set()
        for e in ends:
            on.update(up(e))
        moving = [c for c in on if by_child[c][1] != "fixed"]
        if not 8 <= len(moving) <= 20:
            continue
        # a spare leaf whose branch leaves the tree below a moving joint
        ok = False
        for s in spare:
            path = up(s)
            off = [x for x in path if x not in on]
            attach = by_child[off[-1]][2]
            if any(by_child[x][1] != "fixed" for x in up(attach) if x in on):
                ok = True
        if not ok:
            continue
        break
    lines = ['<?xml version="1.0"?>', '<robot name="random_tree">']
    all_links = links + [f"tip{t}" for t in range(n_tips)]
    for name in all_links:
        if masses and not name.startswith("tip") and name != "base" and rng.random() < 0.85:
            com = _fmt(rng.uniform(-0.1, 0.1, 3))
            m = float(rng.uniform(0.5, 5))
            lines.append(
                f'  <link name="{name}"><inertial><origin xyz="{com}" rpy="0 0 0"/>'
                f'<mass value="{m!r}"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" '
                'iyz="0" izz="0.01"/></inertial></link>'
            )
        else:
            lines.append(f'  <link name="{name}"/>')
    tips_joints = [(f"tipj{t}", "fixed", ends[t], f"tip{t}") for t in range(n_tips)]
    for nm, t, p, c in joints + tips_joints:
        xyz = _fmt(rng.uniform(-0.3, 0.3, 3))
        rpy = _fmt(rng.uniform(-np.pi, np.pi, 3))
        body = f'    <parent link="{p}"/>\n    <child link="{c}"/>\n'
        body += f'    <origin xyz="{xyz}" rpy="{rpy}"/>\n'
        if t != "fixed":
            body += f'    <axis xyz="{_fmt(random_axis(rng))}"/>\n'
        if t == "revolute":
            body += '    <limit lower="-3.0" upper="3.0" effort="100" velocity="2"/>\n'
        lines.append(f'  <joint name="{nm}" type="{t}">\n{body}  </joint>')
    lines.append("</robot>")
    return "\n".join(lines) + "\n", [f"tip{t}" for t in range(n_tips)]


def random_chain_urdf(rng, n: int, fixed_every: int = 3, axes=None):
    """A random serial URDF arm: (text, tip). `n` revolute joints with masses on every
    link, a fixed joint (with its own massive link) after every `fixed_every` of them,
    a massless marker link at the end; `axes` per joint, else random (x/y/z or skew)."""
    lines = ['<?xml version="1.0"?>', '<robot name="random_chain">', '  <link name="base"/>']
    joints, parent, k = [], "base", 0
    for i in range(n):
        child = f"link{i}"
        axis = random_axis(rng) if axes is None else np.asarray(axes[i], float)
        joints.append((f"joint{i}", "revolute", parent, child, axis))
        parent = child
        if fixed_every and (i + 1) % fixed_every == 0:
            child = f"fixed{k}"
            joints.append((f"fixedj{k}", "fixed", parent, child, None))
            parent, k = child, k + 1
    joints.append(("marker_joint", "fixed", parent, "marker", None))
    for _nm, _t, _p, c, _a in joints:
        if c == "marker":
            lines.append(f'  <link name="{c}"/>')
            continue
        com = _fmt(rng.uniform(-0.1, 0.1, 3))
        m = float(rng.uniform(0.5, 5))
        lines.append(
            f'  <link name="{c}"><inertial><origin xyz="{com}" rpy="0 0 0"/>'
            f'<mass value="{m!r}"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" '
            'iyz="0" izz="0.01"/></inertial></link>'
        )
    for nm, t, p, c, axis in joints:
        xyz = _fmt(rng.uniform(-0.3, 0.3, 3))
        rpy = _fmt(rng.uniform(-np.pi, np.pi, 3))
        body = f'    <parent link="{p}"/>\n    <child link="{c}"/>\n'
        body += f'    <origin xyz="{xyz}" rpy="{rpy}"/>\n'
        if t != "fixed":
            body += f'    <axis xyz="{_fmt(axis)}"/>\n'
            body += '    <limit lower="-3.0" upper="3.0" effort="100" velocity="2"/>\n'
        lines.append(f'  <joint name="{nm}" type="{t}">\n{body}  </joint>')
    lines.append("</robot>")
    return "\n".join(lines) + "\n", "marker"
