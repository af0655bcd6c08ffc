"""Properties of random kinematic trees (issue 21), each case from an explicit seed: 2-3
tips off random branch points, random URDF origins and axes, revolute and prismatic
joints, fixed joints between them; some with a random joint coupling (a passive joint
following two others, or a square mix), some measured in 2 sessions.

(i) positions agree with the test's own numpy kinematics of the URDF, and with
roboticstoolbox-python's URDF model where its reader is right (axes along ±x, ±y, ±z),
to 1e-12 m; (ii) the exact
parameter Jacobians agree with central differences; (iii) simulate → write_csv →
read_csv gives the measurements back; (iv) identification from noise-free data of a
perturbed truth either puts the tips where the truth has them on new poses (to 1 µm) or
says it failed: never a success with a wrong answer."""

from __future__ import annotations

import numpy as np
import pytest

import casecal as cc

rtb = pytest.importorskip("roboticstoolbox")

LIMITS = {"revolute": (-2.5, 2.5), "prismatic": (-0.2, 0.3)}


def _joint(name, kind, parent, child, xyz, rpy, axis):
    text = (
        f'  <joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{" ".join(map(repr, xyz))}" rpy="{" ".join(map(repr, rpy))}"/>'
    )
    if kind != "fixed":
        lo, hi = LIMITS[kind]
        text += (
            f'<axis xyz="{" ".join(map(repr, axis))}"/>'
            f'<limit lower="{lo}" upper="{hi}" effort="1" velocity="1"/>'
        )
    return text + "</joint>"


PRINCIPAL = np.vstack([np.eye(3), -np.eye(3)])


def random_tree(rng, n_tips: int, principal: bool = False) -> str:
    """A URDF: a trunk of 1-3 joints, then `n_tips` branches, each off a random link of
    the trunk or of an earlier branch, of 1-3 joints (revolute mostly, prismatic or fixed
    now and then, at least one movable), a fixed marker link `tip{k}` at its end. Axes in
    any direction, or (`principal`) along ±x, ±y, ±z."""
    links, joints = ["root"], []

    def add(kind, parent):
        child = f"l{len(links)}"
        links.append(child)
        axis = PRINCIPAL[rng.integers(6)] if principal else rng.normal(size=3)
        axis = (axis / np.linalg.norm(axis)).tolist()
        xyz, rpy = rng.uniform(-0.3, 0.3, 3).tolist(), rng.uniform(-np.pi, np.pi, 3).tolist()
        joints.append(_joint(f"j{len(links) - 1}", kind, parent, child, xyz, rpy, axis))
        return child

    def kind():
        return rng.choice(["revolute", "prismatic", "fixed"], p=[0.75, 0.15, 0.10])

    grown = [add("revolute", "root")]
    for _ in range(rng.integers(0, 3)):
        grown.append(add(kind(), grown[-1]))
    for t in range(n_tips):
        parent = grown[rng.integers(len(grown))]
        kinds = [kind() for _ in range(rng.integers(1, 4))]
        if all(k == "fixed" for k in kinds):
            kinds[-1] = "revolute"
        for k in kinds:
            parent = add(k, parent)
            grown.append(parent)
        links.append(f"tip{t}")
        xyz = rng.uniform(-0.2, 0.2, 3).tolist()
        joints.append(_joint(f"m{t}", "fixed", parent, f"tip{t}", xyz, [0.1, -0.2, 0.3], None))
    body = "\n".join(f'  <link name="{name}"/>' for name in links)
    return f'<robot name="random_tree">\n{body}\n' + "\n".join(joints) + "\n</robot>\n"


def random_coupling(rng, robot):
    """A passive revolute joint following two other revolute joints (one controller joint
    fewer), or a square mix of two revolute joints; None when it has too few of them."""
    types = robot.joint_types
    revolute = [i for i, t in enumerate(types) if t == "R"]
    if len(revolute) < 3:
        return None
    n = len(types)
    passive, a, b = (int(i) for i in rng.choice(revolute, 3, replace=False))
    coefficients = rng.uniform(0.5, 1.5, 2) * rng.choice([-1.0, 1.0], 2)
    offset = np.zeros(n)
    offset[passive] = rng.uniform(-0.3, 0.3)
    if rng.random() < 0.5:  # square: the model's joint `passive` also turns with `a`
        M = np.eye(n)
        M[passive, a] = coefficients[0]
        return M, offset
    controller = [i for i in range(n) if i != passive]
    M = np.zeros((n, n - 1))
    for c, i in enumerate(controller):
        M[i, c] = 1.0
    M[passive, controller.index(a)] = coefficients[0]
    M[passive, controller.index(b)] = coefficients[1]
    return M, offset


def case(seed: int, tmp_path):
    """The robot of case `seed`: its URDF text, the tree (coupled or not), whether it is
    measured in 2 sessions."""
    rng = np.random.default_rng(seed)
    n_tips = int(rng.integers(2, 4))
    text = random_tree(rng, n_tips, principal=bool(rng.random() < 0.5))
    path = tmp_path / f"tree{seed}.urdf"
    path.write_text(text)
    robot = cc.load_robot(path, tip_link=[f"tip{t}" for t in range(n_tips)])
    coupling = random_coupling(rng, robot) if rng.random() < 0.6 else None
    if coupling is not None:
        robot = robot.with_coupling(*coupling)
    return text, robot, bool(rng.random() < 0.4), rng


def _rpy(r, p, y):
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def own_positions(text: str, robot, q: np.ndarray) -> np.ndarray:
    """The test's own forward kinematics of URDF `text` (numpy: origin, then the joint's
    turn about or slide along its axis) at controller joints `q` mapped to the model's by
    the coupling, (N, tips, 3). Joints off every tip's path stay at 0."""
    import xml.etree.ElementTree as ET

    model = robot.model_joints(q)
    value = {j.name: model[:, i] for i, j in enumerate(robot.joints)}
    n = len(q)
    frames = {"root": np.tile(np.eye(4), (n, 1, 1))}
    for j in ET.fromstring(text).iter("joint"):  # parents before children in these files
        origin, axis = j.find("origin"), j.find("axis")
        T = np.eye(4)
        T[:3, :3] = _rpy(*(float(v) for v in origin.get("rpy").split()))
        T[:3, 3] = [float(v) for v in origin.get("xyz").split()]
        out = frames[j.find("parent").get("link")] @ T
        if axis is not None:
            a = np.array([float(v) for v in axis.get("xyz").split()])
            v = value.get(j.get("name"), np.zeros(n))
            move = np.tile(np.eye(4), (n, 1, 1))
            if j.get("type") == "prismatic":
                move[:, :3, 3] = v[:, None] * a
            else:  # Rodrigues
                K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
                move[:, :3, :3] = (
                    np.eye(3)
                    + np.sin(v)[:, None, None] * K
                    + (1 - np.cos(v))[:, None, None] * (K @ K)
                )
            out = out @ move
        frames[j.find("child").get("link")] = out
    return np.stack([frames[t][:, :3, 3] for t in robot.tips], axis=1)


def oracle_positions(text: str, robot, q: np.ndarray) -> np.ndarray:
    """roboticstoolbox's tip positions at controller joints `q` (mapped to the model's by
    the coupling, the one thing taken from casecal), (N, tips, 3). Its URDF reader (1.5)
    is right for axes along ±x, ±y, ±z only: about (0.6, 0.8, 0) it puts a tip 76 mm
    from where casecal and `own_positions` agree to 1e-16."""
    from roboticstoolbox.models.URDF.URDFRobot import _parse_urdf

    links, name = _parse_urdf(text, source="tree.urdf")
    theirs = rtb.Robot(links, name=name)
    column = {link._joint_name: link.jindex for link in theirs.links if link.isjoint}
    model = robot.model_joints(q)
    qq = np.zeros((len(q), theirs.n))
    for i, joint in enumerate(robot.joints):
        qq[:, column[joint.name]] = model[:, i]
    return np.stack(
        [np.array([theirs.fkine(row, end=tip).A[:3, 3] for row in qq]) for tip in robot.tips],
        axis=1,
    )


def check_case(seed: int, tmp_path, monkeypatch):
    # numpy's evaluation: no kernel compiled for a structure used once
    monkeypatch.setenv("CASECAL_BACKEND", "numpy")
    text, robot, sessions, rng = case(seed, tmp_path)
    tips = len(robot.tips)

    # (i) positions against roboticstoolbox (axes along ±x, ±y, ±z), and the test's own
    q = cc.poses.uniform(robot, 30, seed=seed)
    assert robot.position(q).shape == (30, tips, 3)
    assert np.abs(robot.position(q) - own_positions(text, robot, q)).max() < 1e-12
    principal = all(np.isclose(np.abs(np.array(j.axis)).max(), 1.0) for j in robot.joints)
    if principal:
        assert np.abs(robot.position(q) - oracle_positions(text, robot, q)).max() < 1e-12

    # (ii) exact Jacobians against central differences, at a robot off its nominal
    # about 1 mm and 1 mrad on every parameter: origins, tips' frames, the base
    true = robot.with_deviations({n: rng.normal() * 1e-3 for n in robot.parameter_names})
    q4, h = q[:4], 1e-6
    J, names = true.position_jacobian(q4, "all")
    assert J.shape == (4, 3 * tips, len(names))
    values = true.parameters
    differences = np.empty_like(J)
    for k, name in enumerate(names):
        up = true.with_parameters({name: values[name] + h}).position(q4)
        down = true.with_parameters({name: values[name] - h}).position(q4)
        differences[:, :, k] = ((up - down) / (2 * h)).reshape(4, -1)
    scale = np.abs(J).max()
    assert np.abs(J - differences).max() < 1e-6 * scale

    # (iii) simulate → CSV → read, sessions and all
    labels = np.repeat(["a", "b"], 40) if sessions else None
    frames = {"b": ((0.5, -0.2, 0.1), (0.1, 0.0, 0.8))} if sessions else None
    q_fit = cc.poses.uniform(robot, 80, seed=seed + 100)
    noisy = cc.simulate(true, q_fit, 1e-4, seed=seed, session=labels, frames=frames)
    cc.write_csv(tmp_path / "m.csv", noisy, robot)
    back = cc.read_csv(tmp_path / "m.csv", robot)
    assert back.positions.shape == (80, tips, 3)
    assert np.abs(back.q - noisy.q).max() < 1e-12
    assert np.abs(back.positions - noisy.positions).max() < 1e-12
    assert np.abs(back.sigma - noisy.sigma).max() < 1e-15
    assert (back.session is None) == (not sessions)
    if sessions:
        assert back.session.tolist() == noisy.session.tolist()

    # (iv) noise-free data: the tips where the truth has them, or an honest failure
    exact = cc.simulate(true, q_fit, 0.0, session=labels, frames=frames)
    cal = cc.identify(robot, exact, "all")
    new = cc.poses.uniform(robot, 50, seed=seed + 200)
    error = np.linalg.norm(cal.robot.position(new) - true.position(new), axis=-1).max()
    if cal.success:
        assert error < 1e-6, (seed, error, cal.message)
    else:
        assert cal.status < 0 or not cal.audit.passed, (seed, cal.message)
    kind = "plain" if robot.coupling is None else f"coupled {robot.dof}/{robot.model_dof}"
    axes = "principal" if principal else "any"
    print(
        f"\nseed {seed}: {tips} tips, {axes} axes, {robot.model_dof} joints "
        f"({robot.joint_types}), {kind}, "
        f"{'2 sessions' if sessions else '1 session'}: success {cal.success}, "
        f"held-out max {error * 1e3:.2g} mm"
    )
    return cal.success


@pytest.mark.parametrize("seed", range(4))
def test_random_trees(seed, tmp_path, monkeypatch):
    check_case(seed, tmp_path, monkeypatch)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(4, 50))
def test_more_random_trees(seed, tmp_path, monkeypatch):
    check_case(seed, tmp_path, monkeypatch)
