"""casecal's elastic kinematic trees against implementations nobody on the team wrote.

- `tests/elastic_reference.py`: a numpy walk of the URDF text (xml.etree) with torsion
  and lateral bending written from the model's specification;
- roboticstoolbox-python: its URDF reader, forward kinematics and `gravload`.

Every random draw is seeded.
"""

from __future__ import annotations

import dataclasses
import re
import warnings
from pathlib import Path

import elastic_reference as er
import numpy as np
import pytest

import casecal as cc

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
TWO_ARMS_TIPS = ["right_marker", "left_marker"]
G = er.STANDARD_GRAVITY


def _load(tmp_path, text, tips, name="robot"):
    path = tmp_path / f"{name}.urdf"
    path.write_text(text)
    return cc.load_robot(path, tip_link=list(tips)), er.parse_urdf(text, tips)


def _two_arms(seed, axis=None):
    text = (EXAMPLES / "two_arms.urdf").read_text()
    if axis is not None:  # the torso joint's axis (the example's is vertical: no torque)
        text = text.replace('<axis xyz="0 0 1"/>', f'<axis xyz="{axis}"/>', 1)
    return er.add_inertials(text, np.random.default_rng(seed)), TWO_ARMS_TIPS


def _split(names, joint_names):
    """casecal's compliance values by name -> the reference's {joint: (c, cu, cv)}."""
    out = {}
    for n, v in names.items():
        m = re.fullmatch(r"c(\d+)(?:_([uv]))?", n)
        joint = joint_names[int(m.group(1)) - 1]
        c = list(out.get(joint, (0.0, 0.0, 0.0)))
        c[{None: 0, "u": 1, "v": 2}[m.group(2)]] = v
        out[joint] = tuple(c)
    return out


def _reference(tree, joint_names, q, compliance, gravity=(0, 0, -G)):
    return np.array(
        [
            er.tip_positions(tree, dict(zip(joint_names, qq, strict=True)), compliance, gravity)
            for qq in q
        ]
    )


def _compliances(robot):
    return [n for n in robot.parameter_names if re.fullmatch(r"c\d+(_[uv])?", n)]


def _check_against_reference(robot, tree, seed, n_poses=50):
    rng = np.random.default_rng(seed)
    names = [j.name for j in robot.joints]
    assert names == list(tree.moving)  # the same joints, the same depth-first order
    compliant = robot.with_compliance(lateral=True)
    cs = _compliances(compliant)
    deviations = {n: rng.uniform(1e-4, 5e-4) for n in cs}
    bent = compliant.with_deviations(deviations)
    q = rng.uniform(-2.8, 2.8, (n_poses, len(names)))
    got = bent.position(q)
    want = _reference(tree, names, q, _split(deviations, names))
    rigid = _reference(tree, names, q, {})
    assert np.abs(robot.position(q) - rigid).max() < 1e-12
    # the deflections are large (cm), so that agreement means the model, not a rounding
    assert np.abs(want - rigid).max() > 1e-3
    return cs, got, want, q, names, deviations


# ---------------------------------------------------------------- 1. the reference
def test_two_arms_torsion_and_bending_match_reference(tmp_path):
    text, tips = _two_arms(11)
    robot, tree = _load(tmp_path, text, tips)
    cs, got, want, *_ = _check_against_reference(robot, tree, seed=12)
    assert np.abs(got - want).max() < 1e-10
    # the torso turns about the vertical: no torque on it, but it bends
    assert "c1" not in cs and {"c1_u", "c1_v"} <= set(cs)
    assert set(cs) == {f"c{i}" for i in range(2, 8)} | {
        f"c{i}_{a}" for i in range(1, 8) for a in "uv"
    }


# one seed in the default run; the others with -m slow
@pytest.mark.parametrize(
    "seed", [101, *(pytest.param(s, marks=pytest.mark.slow) for s in (102, 103))]
)
def test_random_tree_torsion_and_bending_match_reference(tmp_path, seed):
    text, tips = er.random_tree_urdf(np.random.default_rng(seed))
    robot, tree = _load(tmp_path, text, tips)
    _, got, want, q, names, deviations = _check_against_reference(robot, tree, seed + 1)
    assert np.abs(got - want).max() < 1e-10
    # the branches that no tip measures carry mass that must count: without it the
    # reference moves the tips by far more than the agreement
    off = [x for x in tree.links if x not in set().union(*(_path(tree, t) for t in tips))]
    assert off
    stripped = er.Tree(
        tree.root,
        {k: (None if k in off else v) for k, v in tree.links.items()},
        tree.joints,
        tree.children,
        tree.tips,
        tree.moving,
    )
    without = _reference(stripped, names, q, _split(deviations, names))
    assert np.abs(without - want).max() > 1e-6


def _path(tree, link):
    """Links from `link` up to the root."""
    out = {link}
    while link in tree.joints:
        link = tree.joints[link].parent
        out.add(link)
    return out


def test_random_tree_tilted_gravity(tmp_path):
    """robot.gravity is a unit vector in the base frame: tilt it."""
    text, tips = er.random_tree_urdf(np.random.default_rng(7))
    robot, tree = _load(tmp_path, text, tips)
    down = np.random.default_rng(8).normal(size=3)
    down /= np.linalg.norm(down)
    tilted = dataclasses.replace(robot, gravity=tuple(down))
    rng = np.random.default_rng(9)
    compliant = tilted.with_compliance(lateral=True)
    deviations = {n: rng.uniform(1e-4, 5e-4) for n in _compliances(compliant)}
    names = [j.name for j in robot.joints]
    q = rng.uniform(-2.8, 2.8, (20, len(names)))
    got = compliant.with_deviations(deviations).position(q)
    want = _reference(tree, names, q, _split(deviations, names), gravity=G * down)
    assert np.abs(got - want).max() < 1e-10


def test_local_bending_is_the_world_turn_at_first_order(tmp_path):
    """The reference composes each bend in its child frame down the tree; the world
    description (D_i about p_i on everything joint i moves) agrees to second order."""
    text, tips = er.random_tree_urdf(np.random.default_rng(21))
    tree = er.parse_urdf(text, tips)
    rng = np.random.default_rng(22)
    compliance = {n: tuple(rng.uniform(1e-4, 5e-4, 3)) for n in tree.moving}
    q = dict(zip(tree.moving, rng.uniform(-2.8, 2.8, len(tree.moving)), strict=True))
    gaps, moves = [], []
    for s in (1e-2, 1e-3):
        small = {n: tuple(s * x for x in c) for n, c in compliance.items()}
        local = er.tip_positions(tree, q, small)
        world = er.tip_positions_world(tree, q, small)
        gaps.append(np.abs(local - world).max())
        moves.append(np.abs(local - er.tip_positions(tree, q)).max())
    assert moves[1] / moves[0] == pytest.approx(0.1, rel=0.05)  # first order
    assert gaps[1] / gaps[0] == pytest.approx(0.01, rel=0.1)  # second order


# ---------------------------------------------------------------- 2. across branches
def test_torso_torque_counts_both_arms(tmp_path):
    """A torso joint with a horizontal axis carries both arms: moving the left arm alone
    changes its torque, hence the right marker's position."""
    text, tips = _two_arms(31, axis="0 1 0")
    robot, tree = _load(tmp_path, text, tips)
    names = [j.name for j in robot.joints]
    compliant = robot.with_compliance(joints=[1])
    assert _compliances(compliant) == ["c1"]
    bent = compliant.with_deviations({"c1": 3e-4})
    rng = np.random.default_rng(32)
    q = rng.uniform(-2.8, 2.8, (20, len(names)))
    q2 = q.copy()
    left = [i for i, n in enumerate(names) if n.startswith("left")]
    q2[:, left] = rng.uniform(-2.8, 2.8, (20, len(left)))
    for qq in (q, q2):
        want = _reference(tree, names, qq, {names[0]: (3e-4, 0.0, 0.0)})
        assert np.abs(bent.position(qq) - want).max() < 1e-10
    right_moves = np.abs(bent.position(q2)[:, 0] - bent.position(q)[:, 0]).max()
    assert np.abs(robot.position(q2)[:, 0] - robot.position(q)[:, 0]).max() < 1e-15
    assert right_moves > 1e-4
    # and the reference without the left arm's masses would miss it
    left_links = {"left_shoulder", "left_upper", "left_fore", "left_wrist", "left_marker"}
    no_left = dataclasses.replace(
        tree, links={k: (None if k in left_links else v) for k, v in tree.links.items()}
    )
    wrong = _reference(no_left, names, q2, {names[0]: (3e-4, 0.0, 0.0)})
    assert np.abs(bent.position(q2) - wrong).max() > 1e-4


# ---------------------------------------------------------------- 3. roboticstoolbox
def _rtb_robot(path):
    rtb = pytest.importorskip("roboticstoolbox")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = rtb.Robot.URDF(str(path))
    robot.gravity = [0.0, 0.0, -G]
    return robot


def _rtb_potential_gradient(rtb_robot, q, h=1e-6):
    """-∂V/∂q by central differences, V from rtb's link poses and rtb's parsed masses and
    centres of mass: gravity's torque per joint (N·m)."""
    g = np.array([0.0, 0.0, -G])

    def V(x):
        return -sum(
            link.m * g @ (rtb_robot.fkine(x, end=link.name).A @ np.r_[link.r, 1.0])[:3]
            for link in rtb_robot.links
            if link.m
        )

    return -np.array([(V(q + h * e) - V(q - h * e)) / (2 * h) for e in np.eye(len(q))])


def _tip(robot, q):
    """The one tip of a serial robot at one pose, (3,)."""
    return np.asarray(robot.position(q[None])).reshape(-1)[:3]


def _casecal_torsion_is(robot, q, tau, c=1e-3):
    """casecal's torsion with every c{i} = c equals the rigid robot at q + c·tau."""
    n = len(robot.joints)
    compliant = robot.with_compliance(joints=list(range(1, n + 1)))
    bent = compliant.with_deviations({f"c{i}": c for i in range(1, n + 1)})
    got = bent.position(q[None])[0]
    want = robot.position((q + c * tau)[None])[0]
    # a wrong torque by 1e-6 N·m moves the tip by ~1e-9·lever
    return np.abs(got - want).max()


@pytest.mark.parametrize("seed", [41, 42, 43])
def test_torsion_matches_rtb_gravload_on_z_axis_chain(tmp_path, seed):
    """rtb's gravload (Newton-Euler) is the motors' holding torque, minus gravity's."""
    rng = np.random.default_rng(seed)
    text, tip = er.random_chain_urdf(rng, 6, fixed_every=0, axes=[(0, 0, 1)] * 6)
    path = tmp_path / "chain.urdf"
    path.write_text(text)
    robot = cc.load_robot(path, tip_link=tip)
    arm = _rtb_robot(path)
    for q in rng.uniform(-2.8, 2.8, (5, 6)):
        assert np.abs(arm.fkine(q).t - _tip(robot, q)).max() < 1e-12
        tau = -arm.gravload(q)
        assert np.abs(tau).max() > 1.0
        assert _casecal_torsion_is(robot, q, tau) < 1e-10
        assert _casecal_torsion_is(robot, q, -tau) > 1e-4  # the sign matters


@pytest.mark.parametrize("seed", [51, 52])
def test_torsion_matches_rtb_potential_on_any_chain(tmp_path, seed):
    """x, y and z axes, massive links behind fixed joints: gravity's torque as the gradient of
    the potential energy that rtb's own kinematics and parsed inertials give."""
    rng = np.random.default_rng(seed)
    # principal axes: rtb 1.5.0's URDF reader turns a skew axis's link frame to put the
    # axis on z and never turns it back (its forward kinematics then differ from the URDF)
    principal = [np.roll([float(rng.choice([-1, 1])), 0.0, 0.0], k) for k in rng.integers(0, 3, 6)]
    text, tip = er.random_chain_urdf(rng, 6, fixed_every=2, axes=principal)
    path = tmp_path / "chain.urdf"
    path.write_text(text)
    robot = cc.load_robot(path, tip_link=tip)
    arm = _rtb_robot(path)
    for q in rng.uniform(-2.8, 2.8, (3, 6)):
        assert np.abs(arm.fkine(q).t - _tip(robot, q)).max() < 1e-12
        tau = _rtb_potential_gradient(arm, q)
        assert _casecal_torsion_is(robot, q, tau) < 1e-7  # differences: ~1e-8 N·m


# ---------------------------------------------------------------- 4. exact Jacobians
@pytest.mark.parametrize("seed", [61, pytest.param(62, marks=pytest.mark.slow)])
def test_jacobian_of_compliances_matches_differences(tmp_path, seed):
    rng = np.random.default_rng(seed)
    text, tips = er.random_tree_urdf(rng)
    robot, _tree = _load(tmp_path, text, tips)
    compliant = robot.with_compliance(lateral=True)
    cs = _compliances(compliant)
    base = compliant.with_deviations(dict.fromkeys(cs, 2e-4))
    geometric = [n for n in robot.parameter_names if not n.startswith(tuple(tips))]
    picked = list(rng.choice(geometric, size=6, replace=False))
    names = cs + picked
    q = rng.uniform(-2.8, 2.8, (20, len(robot.joints)))
    J, got_names = base.position_jacobian(q, names, deviations=True)
    assert sorted(got_names) == sorted(names)  # in the robot's order
    names = list(got_names)
    assert J.shape == (20, 3 * len(tips), len(names))
    for k, name in enumerate(names):
        h = 1e-8 if name in cs else 1e-7  # 5e-5 of the compliances' 2e-4
        plus = base.with_deviations({name: h}).position(q).reshape(20, -1)
        minus = base.with_deviations({name: -h}).position(q).reshape(20, -1)
        fd = (plus - minus) / (2 * h)
        scale = np.abs(fd).max()
        assert scale > 0, name
        assert np.abs(J[:, :, k] - fd).max() < 1e-6 * scale, name


# ---------------------------------------------------------------- 5. no masses
def test_tree_without_masses_lumped_terms(tmp_path):
    text, tips = er.random_tree_urdf(np.random.default_rng(71), masses=False)
    robot, tree = _load(tmp_path, text, tips)
    assert all(x is None for x in robot.inertials) or not robot.inertials
    with pytest.raises(cc.CalibrationError, match="mass"):
        robot.with_compliance(lateral=True)
    names = [j.name for j in robot.joints]
    child = {j.name: c for c, j in tree.joints.items()}
    lumped = robot.with_compliance()
    found: dict = {}
    for n in lumped.parameter_names:
        m = re.fullmatch(r"g(\d+)_(\d+)([mxyz])", n)
        if m:
            found.setdefault(int(m.group(1)), {}).setdefault(int(m.group(2)), set()).add(m.group(3))
    assert len(found) >= len(names) - 1
    for i, per_k in found.items():
        under = set(tree.below(child[names[i - 1]]))
        expected = {k + 1 for k, n in enumerate(names) if child[n] in under}
        assert set(per_k) == expected, i
        assert all(v == set("mxyz") for v in per_k.values())


def test_lumped_terms_equal_masses(tmp_path):
    """The lumped terms set from the masses (g{i}_{k}m = c·m_k·g, g{i}_{k}x/y/z =
    c·m_k·g·r_k, r_k the centre of mass of body k in its frame) give the reference's
    torsion; body k = joint k's child link, the links fixed to it and branches no tip
    measures."""
    text, tips = er.random_tree_urdf(np.random.default_rng(81))
    tree = er.parse_urdf(text, tips)
    bare = re.sub(r"<inertial>.*?</inertial>", "", text)
    robot, _ = _load(tmp_path, bare, tips)
    names = [j.name for j in robot.joints]
    child = {j.name: c for c, j in tree.joints.items()}
    T = er._frames(tree, {})  # bodies' contents are fixed to them: any pose
    body_of = {}
    for link in tree.walk():
        up = link
        while up in tree.joints and tree.joints[up].name not in names:
            up = tree.joints[up].parent
        body_of[link] = names.index(tree.joints[up].name) + 1 if up in tree.joints else None
    mass, moment = {}, {}
    for link, inertial in tree.links.items():
        k = body_of[link]
        if inertial is None or k is None:
            continue
        m, com = inertial
        frame = T[child[names[k - 1]]]
        r = frame[:3, :3].T @ (T[link][:3, :3] @ com + T[link][:3, 3] - frame[:3, 3])
        mass[k] = mass.get(k, 0.0) + m
        moment[k] = moment.get(k, np.zeros(3)) + m * r
    rng = np.random.default_rng(82)
    c = {i: rng.uniform(1e-4, 5e-4) for i in range(1, len(names) + 1)}
    lumped = robot.with_compliance()
    values = {}
    for n in lumped.parameter_names:
        m = re.fullmatch(r"g(\d+)_(\d+)([mxyz])", n)
        if m:
            i, k, a = int(m.group(1)), int(m.group(2)), m.group(3)
            if a == "m":
                values[n] = c[i] * mass.get(k, 0.0) * G
            else:
                values[n] = c[i] * moment.get(k, np.zeros(3))["xyz".index(a)] * G
    q = rng.uniform(-2.8, 2.8, (20, len(names)))
    got = lumped.with_deviations(values).position(q)
    present = {int(re.match(r"g(\d+)_", n).group(1)) for n in values}
    want = _reference(tree, names, q, {names[i - 1]: (c[i], 0.0, 0.0) for i in present})
    assert np.abs(got - want).max() < 1e-10


# ---------------------------------------------------------------- one tip of a tree
# One tip loads the serial chain (casecal.model.urdf.read_urdf): its joints carry the same
# bodies as in the tree (found on f192c68, where the chain carried only the links on the
# path to its tip: 3 cm off on two_arms, 15-18 cm on random trees, 2.5 mm for a hand
# modelled after the tip).


def test_one_tip_of_two_arms_still_carries_the_other_arm(tmp_path):
    """The right arm alone, from the two-arm URDF with a horizontal torso axis: the left
    arm still hangs on the torso, and its weight turns the torso joint."""
    text, _ = _two_arms(91, axis="0 1 0")
    path = tmp_path / "two_arms.urdf"
    path.write_text(text)
    serial = cc.load_robot(path, tip_link="right_marker")
    tree = er.parse_urdf(text, ["right_marker"])
    names = [j.name for j in serial.joints]
    assert names == list(tree.moving)
    bent = serial.with_compliance(joints=[1]).with_deviations({"c1": 3e-4})
    q = np.random.default_rng(92).uniform(-2.8, 2.8, (20, len(names)))
    got = np.asarray(bent.position(q)).reshape(20, -1, 3)
    want = _reference(tree, names, q, {names[0]: (3e-4, 0.0, 0.0)})
    # the same file as a tree agrees with the reference (test_torso_torque_counts_both_arms)
    assert np.abs(got - want).max() < 1e-10


@pytest.mark.parametrize("seed", [401, pytest.param(402, marks=pytest.mark.slow)])
def test_one_tip_of_a_random_tree_matches_reference(tmp_path, seed):
    text, tips = er.random_tree_urdf(np.random.default_rng(seed))
    path = tmp_path / "tree.urdf"
    path.write_text(text)
    serial = cc.load_robot(path, tip_link=tips[0])
    tree = er.parse_urdf(text, tips[:1])
    names = [j.name for j in serial.joints]
    assert names == list(tree.moving)
    rng = np.random.default_rng(seed + 1)
    compliant = serial.with_compliance(lateral=True)
    deviations = {n: rng.uniform(1e-4, 5e-4) for n in _compliances(compliant)}
    q = rng.uniform(-2.8, 2.8, (20, len(names)))
    rigid = np.asarray(serial.position(q)).reshape(20, -1, 3)
    assert np.abs(rigid - _reference(tree, names, q, {})).max() < 1e-12
    got = np.asarray(compliant.with_deviations(deviations).position(q)).reshape(20, -1, 3)
    want = _reference(tree, names, q, _split(deviations, names))
    assert np.abs(got - want).max() < 1e-10


def test_one_tip_inside_a_chain_carries_what_lies_beyond(tmp_path):
    """A marker on link3 of a six-joint arm: links 4 and 5 (say, a hand) still weigh on
    joints 0…3, at their joints' zero."""
    text, _ = er.random_chain_urdf(np.random.default_rng(5), 6, fixed_every=0)
    path = tmp_path / "chain.urdf"
    path.write_text(text)
    serial = cc.load_robot(path, tip_link="link3")
    tree = er.parse_urdf(text, ["link3"])
    names = [j.name for j in serial.joints]
    assert names == list(tree.moving)
    every = list(range(1, len(names) + 1))
    bent = serial.with_compliance(joints=every).with_deviations({f"c{i}": 3e-4 for i in every})
    q = np.random.default_rng(6).uniform(-2.8, 2.8, (10, len(names)))
    got = np.asarray(bent.position(q)).reshape(10, -1, 3)
    want = _reference(tree, names, q, {n: (3e-4, 0.0, 0.0) for n in names})
    assert np.abs(got - want).max() < 1e-10
