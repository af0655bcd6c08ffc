"""Rotations without the roll-pitch-yaw singularity (issue 19, case 9).

URDF origins at pitch ±90° (``rpy="r 1.5708 y"``) made fits on exact data stall: there the
roll and yaw columns are parallel and no angle turns the frame about the third axis. The
true robots here are written independently of casecal's rotation code: each frame turned
by a random rotation vector with scipy, its roll, pitch and yaw from scipy too, and read
back from a URDF file (or set with `with_parameters`).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import casecal as cc
from casecal.model import kinematics
from casecal.model.frames import matrix_from_rpy, rpy_from_matrix
from casecal.model.rotation_chart import deviate, deviation

H = math.pi / 2
ROUND = (0.0, H, -H, math.pi)  # the roll and yaw of real URDFs
ROTATIONS = (".roll", ".pitch", ".yaw", "_rx", "_ry", "_rz")
STEP = 1e-6  # rad or m: central differences, truncation ~1e-12, rounding ~1e-10


def _numbers(values) -> str:
    return " ".join(repr(float(v)) for v in values)


def _urdf(origins, tool) -> str:
    """A serial chain of revolute joints about z with the given (xyz, rpy) origins, and a
    fixed joint to ``tool0``."""
    links, joints, parent = ['<link name="base_link"/>'], [], "base_link"
    for i, (xyz, rpy) in enumerate(origins, start=1):
        links.append(f'<link name="link{i}"/>')
        joints.append(
            f'<joint name="j{i}" type="revolute"><parent link="{parent}"/>'
            f'<child link="link{i}"/><origin xyz="{_numbers(xyz)}" rpy="{_numbers(rpy)}"/>'
            '<axis xyz="0 0 1"/><limit lower="-2.5" upper="2.5" effort="1" velocity="1"/>'
            "</joint>"
        )
        parent = f"link{i}"
    links.append('<link name="tool0"/>')
    joints.append(
        f'<joint name="flange" type="fixed"><parent link="{parent}"/><child link="tool0"/>'
        f'<origin xyz="{_numbers(tool[0])}" rpy="{_numbers(tool[1])}"/></joint>'
    )
    return '<robot name="gimbal">' + "".join(links + joints) + "</robot>"


def _turned(rng, xyz, rpy, angle=1e-3, shift=1e-3):
    """`xyz` moved by about `shift` and `rpy` turned by about `angle`, in any direction."""
    R = Rotation.from_euler("xyz", rpy) * Rotation.from_rotvec(rng.normal(size=3) * angle)
    return np.asarray(xyz) + rng.normal(size=3) * shift, R.as_euler("xyz")


def _pair(tmp_path, pitches, seed, tool_pitch=0.0):
    """The nominal and the true robot of a chain whose origins have the given pitches."""
    rng = np.random.default_rng(seed)
    origins = [
        (rng.uniform(-0.3, 0.3, 3), (rng.choice(ROUND), p, rng.choice(ROUND))) for p in pitches
    ]
    tool = ([0.05, 0.02, 0.1], (rng.choice(ROUND), tool_pitch, rng.choice(ROUND)))
    (tmp_path / "nominal.urdf").write_text(_urdf(origins, tool))
    true = _urdf([_turned(rng, *o) for o in origins], _turned(rng, *tool))
    (tmp_path / "true.urdf").write_text(true)
    return cc.load_robot(tmp_path / "nominal.urdf"), cc.load_robot(tmp_path / "true.urdf")


def _assert_recovered(cal, true, poses: int = 400):
    """The fit reached the rounding floor of exact data and the calibrated robot's forward
    kinematics is the true robot's across the joint ranges."""
    assert cal.success, cal.message
    assert np.sqrt(np.mean(cal.residuals**2)) < 1e-12  # m: rounding, not a stall
    q = cc.poses.uniform(true, poses, seed=11)
    ours, theirs = cal.robot.fk(q), true.fk(q)
    assert np.abs(ours[:, :3, 3] - theirs[:, :3, 3]).max() <= 1e-9  # m
    assert np.abs(ours[:, :3, :3] - theirs[:, :3, :3]).max() <= 1e-9  # rad, about


def _fit(nominal, true, n: int = 40, parameters="all"):
    q = cc.poses.uniform(nominal, n, seed=5)
    meas = cc.simulate(true, q, noise=0.0, orientation_noise=0.0)
    return cc.identify(nominal, meas, parameters)


# --- fits -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "away, seed",
    [
        (0.0, 0),  # pitch exactly ±π/2 (the nearest doubles): main stalled, 0.16 mm off
        (0.0, 6),  # main said success 0.11 mm off the true robot
        (1e-6, 1),  # 1e-6 rad inside
        (H - 1.5708, 1),  # the files' 1.5708, 3.7e-6 rad outside
    ],
)
def test_a_urdf_chain_at_pitch_90_is_recovered_exactly(tmp_path, away, seed):
    pitches = [(H - away) * (-1) ** i for i in range(6)]  # +90°, -90°, +90° ...
    nominal, true = _pair(tmp_path, pitches, seed)
    _assert_recovered(_fit(nominal, true), true)


def _dh_with_frame(frame: str, rpy):
    robot = cc.load_robot("puma560").with_parameters({"tool_z": 0.1, "base_x": 0.3})
    return robot.with_parameters(dict(zip([f"{frame}_r{a}" for a in "xyz"], rpy, strict=True)))


def _turned_about_the_lock(robot, frame: str, angle: float):
    """`robot` with `frame` turned about the one axis that no angle turns it about at pitch
    ±90°: the frame's own ``Rx(-roll) z`` (never its roll's x, nor its pitch's axis)."""
    rpy = [robot.parameters[f"{frame}_r{a}"] for a in "xyz"]
    axis = Rotation.from_euler("x", -rpy[0]).apply([0.0, 0.0, 1.0])
    turned = Rotation.from_euler("xyz", rpy) * Rotation.from_rotvec(axis * angle)
    values = dict(zip([f"{frame}_r{a}" for a in "xyz"], turned.as_euler("xyz"), strict=True))
    return robot.with_parameters(values)


@pytest.mark.parametrize("pitch", [H, -(H - 1e-6)])
def test_a_tool_frame_at_pitch_90_is_recovered_exactly(pitch):
    # yaw 90°: the locked axis is the flange's y, which no DH parameter of the wrist turns
    nominal = _dh_with_frame("tool", (0.0, pitch, H))
    true = _turned_about_the_lock(nominal, "tool", 2e-3)
    _assert_recovered(_fit(nominal, true, 60), true)


@pytest.mark.parametrize("pitch", [H, -(H - 1e-6)])
def test_a_base_frame_at_pitch_90_is_recovered_exactly(pitch):
    # roll 90°: the locked axis is the base's y, which θ1 (about its z) cannot stand for;
    # the base's rotation asked for alone, so no rigid fit of the data moves the frame
    nominal = _dh_with_frame("base", (H, pitch, 0.0))
    true = _turned_about_the_lock(nominal, "base", 2e-3)
    _assert_recovered(_fit(nominal, true, 60, "theta*,d*,a*,alpha*,beta*,base_r*,tool_*"), true)


# --- the deviation itself ---------------------------------------------------------------


def _reference(rpy0, delta) -> np.ndarray:
    """``Rz(y0) Ry(p0) Rz(δyaw) Ry(δpitch) Rx(r0 + δroll)`` by scipy (intrinsic axes)."""
    r0, p0, y0 = rpy0
    dr, dp, dy = delta
    turn = Rotation.from_euler("ZY", [y0, p0]) * Rotation.from_euler("ZYX", [dy, dp, r0 + dr])
    return turn.as_matrix()


@pytest.mark.parametrize("pitch", [H, -H, H - 1e-6, 0.4, 0.0])
def test_the_deviation_is_the_documented_rotation_and_inverts(pitch):
    rng = np.random.default_rng(3)
    for _ in range(50):
        rpy0 = (rng.uniform(-math.pi, math.pi), pitch, rng.uniform(-math.pi, math.pi))
        delta = rng.normal(size=3) * 1e-2
        rpy = deviate(rpy0, delta)
        assert np.abs(matrix_from_rpy(rpy) - _reference(rpy0, delta)).max() < 1e-15
        assert np.abs(np.subtract(deviation(rpy0, rpy), delta)).max() < 1e-14


def test_with_deviations_still_adds_where_the_pitch_is_zero():
    """Frames at pitch 0 (most base and tool frames, most URDF origins) deviate as before,
    to the bit; elsewhere roll and pitch still add, and yaw adds if alone at pitch 0."""
    robot = cc.load_robot("puma560").with_parameters({"tool_rx": 0.3, "tool_rz": -1.2})
    d = {"tool_rx": 1e-3, "tool_ry": -2e-3, "tool_rz": 3e-3, "base_rz": 0.5}
    p, moved = robot.parameters, robot.with_deviations(d).parameters
    assert all(moved[n] == p[n] + v for n, v in d.items())
    pitched = robot.with_parameters({"tool_ry": 0.7})
    moved = pitched.with_deviations({"tool_rx": 1e-3, "tool_ry": -2e-3}).parameters
    assert moved["tool_rx"] == 0.3 + 1e-3 and moved["tool_ry"] == 0.7 - 2e-3


def test_rpy_from_matrix_rebuilds_the_rotation_near_the_lock():
    """Roll and yaw each ill-determined at pitch ±90°, yet the rebuilt matrix must be the
    given one to rounding (taken each from its own entries, they were off by ε/cos)."""
    rng = np.random.default_rng(4)
    worst = 0.0
    for away in (1e-3, 1e-6, 1e-9, 1e-12, 0.0):
        for sign in (1, -1):
            for _ in range(40):
                rpy = (rng.uniform(-3, 3), sign * (H - away), rng.uniform(-3, 3))
                # a product of rotations: entries with their own rounding, as a fold has
                R = (
                    Rotation.from_euler("xyz", rpy).as_matrix()
                    @ Rotation.from_rotvec(rng.normal(size=3) * 1e-13).as_matrix()
                )
                worst = max(worst, np.abs(matrix_from_rpy(rpy_from_matrix(R)) - R).max())
    assert worst < 1e-15


# --- Jacobian columns against central differences ---------------------------------------


def _differences(robot, q, names):
    """Central differences of fk in each deviation (`with_deviations`), (N, 6, k):
    position rows in m, rotation-vector rows (world frame) in rad."""
    R0 = robot.fk(q)[:, :3, :3]
    columns = []
    for name in names:
        plus = robot.with_deviations({name: STEP}).fk(q)
        minus = robot.with_deviations({name: -STEP}).fk(q)
        dpos = (plus[:, :3, 3] - minus[:, :3, 3]) / (2 * STEP)
        W = (plus[:, :3, :3] - minus[:, :3, :3]) / (2 * STEP) @ np.swapaxes(R0, 1, 2)
        W = 0.5 * (W - np.swapaxes(W, 1, 2))
        columns.append(np.hstack([dpos, np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], 1)]))
    return np.stack(columns, axis=2)


def _locked_robots(tmp_path):
    urdf, _ = _pair(tmp_path, [H, -H, H - 1e-6, 0.3, -(H - 1e-6), H], seed=7, tool_pitch=H)
    dh = _dh_with_frame("tool", (0.4, -H, 1.1)).with_parameters(
        {"base_rx": -0.3, "base_ry": H, "base_rz": 2.0}
    )
    return urdf, dh


def test_deviation_columns_match_central_differences_and_are_never_parallel(tmp_path):
    for robot in _locked_robots(tmp_path):
        rotations = [n for n in robot.parameter_names if n.endswith(ROTATIONS)]
        q = cc.poses.uniform(robot, 8, seed=1)
        J, names = robot.pose_jacobian(q, rotations, deviations=True)
        FD = _differences(robot, q, names)
        assert np.abs(J - FD).max() < 1e-8
        # the three of each frame turn it about orthonormal axes: singular values all 1
        for k in range(0, len(names), 3):
            s = np.linalg.svd(J[:, 3:, k : k + 3], compute_uv=False)
            assert np.abs(s - 1.0).max() < 1e-12, names[k]


def test_the_columns_in_the_angles_are_unchanged_and_relate_as_documented(tmp_path):
    """Without `deviations`, the Jacobian is the angles' (parallel roll and yaw at the lock);
    to first order the yaw angle is ``cos p0 · δyaw - sin p0 · δroll``."""
    for robot in _locked_robots(tmp_path):
        q = cc.poses.uniform(robot, 5, seed=2)
        triples = [
            [n, n.replace("roll", "pitch"), n.replace("roll", "yaw")]
            for n in robot.parameter_names
            if n.endswith(".roll")
        ] + [[f"{f}_rx", f"{f}_ry", f"{f}_rz"] for f in ("base", "tool")]
        for roll, pitch, yaw in triples:
            angles, _ = robot.pose_jacobian(q, [roll, pitch, yaw])
            turns, _ = robot.pose_jacobian(q, [roll, pitch, yaw], deviations=True)
            p = robot.parameters[pitch]
            np.testing.assert_allclose(angles[..., :2], turns[..., :2], rtol=0, atol=1e-12)
            expected = math.cos(p) * turns[..., 2] - math.sin(p) * turns[..., 0]
            np.testing.assert_allclose(angles[..., 2], expected, rtol=0, atol=1e-12)


def test_the_fit_jacobian_is_exact_away_from_its_anchor(tmp_path):
    """A fit evaluates ``p0 + x`` about the anchor ``p0``: value and columns are those of
    ``robot.with_deviations(x)`` and its derivatives in x, also for x far from 0."""
    robot, _ = _locked_robots(tmp_path)
    chain = kinematics.chain(robot.structure)
    names = [n for n in robot.parameter_names if n.startswith(("j2.", "j5.", "tool_"))]
    columns = chain.columns(names)
    x = np.random.default_rng(8).normal(size=len(names)) * 0.05
    p0 = robot.vector()
    p = p0.copy()
    p[list(columns)] += x
    q = cc.poses.uniform(robot, 6, seed=3)
    value = chain.evaluate("fk", q, p, anchor=p0)
    at = robot.with_deviations(dict(zip(names, x, strict=True)))
    assert np.abs(value - at.fk(q)).max() < 1e-14
    J = chain.evaluate("position_jacobian", q, p, columns, anchor=p0)
    for k, name in enumerate(names):
        step = STEP * (np.arange(len(x)) == k)
        up = robot.with_deviations(dict(zip(names, x + step, strict=True)))
        down = robot.with_deviations(dict(zip(names, x - step, strict=True)))
        fd = (up.position(q) - down.position(q)) / (2 * STEP)
        assert np.abs(J[:, :, k] - fd).max() < 1e-8, name


# --- what a fit reports and saves ---------------------------------------------------------


def test_the_reported_deviations_rebuild_the_calibrated_robot_and_it_saves(tmp_path):
    nominal, true = _pair(tmp_path, [H, -H, H, -H, H, -H], seed=0)
    cal = _fit(nominal, true)
    rebuilt = nominal.with_deviations(cal.deviations)
    q = cc.poses.uniform(nominal, 100, seed=6)
    assert np.abs(rebuilt.fk(q) - cal.robot.fk(q)).max() < 1e-12
    cc.save_robot(cal.robot, tmp_path / "calibrated.urdf")
    base = np.eye(4)
    base[:3, :3] = matrix_from_rpy(cal.robot.base.rpy)
    base[:3, 3] = cal.robot.base.xyz
    back = cc.load_robot(tmp_path / "calibrated.urdf").fk(q)  # the URDF holds no base frame
    assert np.abs(base @ back - cal.robot.fk(q)).max() < 1e-12


def test_a_tracker_standing_upright_gets_deviations_and_errors_of_the_turn():
    """The base at pitch 90° (an upright tracker), noisy data, the whole base fitted in the
    rigid-fit frame and mapped back: the base's three rotations get finite standard errors
    and deviations within them of the truth's, a pure pitch (δyaw = 0: a turn and a sum
    agree, as test_the_deviation_is_the_documented_rotation_and_inverts checks against
    scipy). Main held base_rz (standard error NaN) and reported roll and yaw 1.2 mrad off."""
    robot = cc.load_robot("puma560").with_points([[0.05, 0.02, 0.1]])
    robot = robot.with_parameters({"base_x": 2.0, "base_rx": 0.3, "base_ry": H, "base_rz": -0.5})
    true = robot.with_parameters({"base_x": 2.001, "base_ry": H - 1e-3})
    q = cc.poses.uniform(robot, 80, seed=1)
    cal = cc.identify(robot, cc.simulate(true, q, noise=2e-5, seed=2), "all")
    assert cal.success, cal.message
    truth = {"base_x": 1e-3, "base_rx": 0.0, "base_ry": -1e-3, "base_rz": 0.0}
    for name, value in truth.items():
        se = cal.standard_errors[name]
        assert 0 < se < 1e-5, name  # m or rad
        assert abs(cal.deviations[name] - value) < 4 * se, name
