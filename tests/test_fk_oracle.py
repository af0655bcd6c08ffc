"""Forward kinematics against roboticstoolbox-python, an implementation nobody here wrote."""

from __future__ import annotations

import dataclasses
import tomllib

import numpy as np
import pytest
import roboticstoolbox as rtb
from conftest import random_robot_toml
from hypothesis import given, settings
from hypothesis import strategies as st
from spatialmath import SE3

import casecal as cc
from casecal.model.catalog import robot_from_dict

TOL = 1e-12  # metres (and dimensionless for rotation entries)

CATALOG_ORACLES = {
    "puma560": rtb.models.DH.Puma560,
    "rr": rtb.models.DH.Planar2,
    "rrr": rtb.models.DH.Planar3,
    "scara": rtb.models.DH.Cobra600,
    "kr5_arc": rtb.models.DH.KR5,
    "irb140": rtb.models.DH.IRB140,
}


def rtb_fk(model, q: np.ndarray) -> np.ndarray:
    return np.array([model.fkine(qi).A for qi in q])


@pytest.mark.parametrize("name", sorted(CATALOG_ORACLES))
def test_catalog_fk_matches_roboticstoolbox(name):
    robot = cc.load_robot(name)
    oracle = CATALOG_ORACLES[name]()
    q = cc.poses.uniform(robot, 50, seed=1)
    ours = robot.fk(q)
    assert ours.shape == (50, 4, 4)
    np.testing.assert_allclose(ours, rtb_fk(oracle, q), rtol=0, atol=TOL)
    # the compiled-C path (large batches) must agree with the CasADi path
    q_big = cc.poses.uniform(robot, 400, seed=2)
    np.testing.assert_allclose(robot.fk(q_big)[:7], rtb_fk(oracle, q_big[:7]), rtol=0, atol=TOL)
    np.testing.assert_allclose(robot.position(q), ours[:, :3, 3], rtol=0, atol=0)


def test_single_pose_shapes():
    robot = cc.load_robot("puma560")
    q = np.zeros(6)
    assert robot.fk(q).shape == (4, 4)
    assert robot.position(q).shape == (3,)
    J, names = robot.position_jacobian(q, "theta*")
    assert J.shape == (3, 6) and names == [f"theta{i}" for i in range(1, 7)]
    # Corke's PUMA at q = 0: tool point at (a2 + ... ) -- read off rtb, not ourselves
    np.testing.assert_allclose(robot.position(q), rtb.models.DH.Puma560().fkine(q).t, atol=TOL)


def oracle_for(convention: str, si: dict) -> rtb.DHRobot:
    links = []
    for j in si["joints"]:
        if convention == "dh":
            if j["type"] == "R":
                links.append(
                    rtb.RevoluteDH(d=j["d"], a=j["a"], alpha=j["alpha"], offset=j["theta"])
                )
            else:
                links.append(
                    rtb.PrismaticDH(theta=j["theta"], a=j["a"], alpha=j["alpha"], offset=j["d"])
                )
        elif j["type"] == "R":
            links.append(rtb.RevoluteMDH(d=j["d"], a=j["a"], alpha=j["alpha"], offset=j["theta"]))
        else:
            links.append(
                rtb.PrismaticMDH(theta=j["theta"], a=j["a"], alpha=j["alpha"], offset=j["d"])
            )

    def frame(f):  # spatialmath's 'zyx' RPY is Rz(yaw) Ry(pitch) Rx(roll), as documented
        return SE3(*f["xyz"]) * SE3.RPY(f["rpy"], order="zyx")

    return rtb.DHRobot(links, base=frame(si["base"]), tool=frame(si["tool"]))


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    convention=st.sampled_from(["dh", "mdh"]),
    n=st.integers(1, 7),
    length_unit=st.sampled_from(["m", "mm"]),
    angle_unit=st.sampled_from(["rad", "deg"]),
)
def test_random_toml_robots_match_roboticstoolbox(
    tmp_path_factory, seed, convention, n, length_unit, angle_unit
):
    rng = np.random.default_rng(seed)
    text, si = random_robot_toml(rng, convention, n, length_unit=length_unit, angle_unit=angle_unit)
    path = tmp_path_factory.mktemp("robots") / "random.toml"
    path.write_text(text)
    robot = cc.load_robot(path)
    assert robot.joint_types == "".join(j["type"] for j in si["joints"])
    q = cc.poses.uniform(robot, 20, seed=seed)
    # mm/deg files are converted to SI, so rounding of the conversion shows at ~1e-15 m
    np.testing.assert_allclose(robot.fk(q), rtb_fk(oracle_for(convention, si), q), rtol=0, atol=TOL)


@pytest.mark.parametrize("convention", ["dh", "mdh"])
def test_hayati_beta_is_a_rotation_about_the_link_y_axis(convention):
    """A non-zero beta, checked against rtb's link transforms times a numpy Ry(beta)."""
    rng = np.random.default_rng(7)
    text, si = random_robot_toml(
        rng, convention, 5, length_unit="m", angle_unit="rad", parallel=False
    )
    robot = robot_from_dict(tomllib.loads(text))
    betas = {f"beta{i}": 0.03 * i for i in range(1, 6)}
    # give every link a beta explicitly, whatever the auto rule would do
    joints = tuple(
        dataclasses.replace(j, beta=betas[f"beta{i}"]) for i, j in enumerate(robot.joints, start=1)
    )
    robot = dataclasses.replace(robot, joints=joints, auto_beta=False)
    oracle = oracle_for(convention, si)
    q = cc.poses.uniform(robot, 10, seed=3)

    def ry(b):
        c, s = np.cos(b), np.sin(b)
        return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1]])

    expected = []
    for qi in q:
        T = oracle.base.A
        for i, link in enumerate(oracle.links):
            A = link.A(qi[i]).A
            if convention == "dh":  # Rz Tz Tx Rx, then Ry(beta)
                T = T @ A @ ry(betas[f"beta{i + 1}"])
            else:  # Rx Ry(beta) Tx Rz Tz: insert Ry after the leading Rx(alpha)
                j = si["joints"][i]
                rx = SE3.Rx(j["alpha"]).A
                T = T @ rx @ ry(betas[f"beta{i + 1}"]) @ np.linalg.solve(rx, A)
        expected.append(T @ oracle.tool.A)
    np.testing.assert_allclose(robot.fk(q), np.array(expected), rtol=0, atol=TOL)
