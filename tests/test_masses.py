"""Masses and centres of mass as parameters (issue 22, `casecal.model.masses`).

Exact Jacobians against central differences on an elastic tree; the same robot with its
masses as parameters at their CAD values is the same robot; a heavy arm whose hand is
heavier than its CAD says: with that body's mass a parameter, the fit finds it (against
the simulation's truth) and reaches the noise floor, where the CAD's mass leaves a model
error. The data see a mass only through what it bends: the fit says so where they cannot.
"""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

import casecal as cc
from casecal.report.studies_compliance import INERTIALS

TWO_ARMS = """<robot name="two"><link name="base"/>
<link name="torso"><inertial><mass value="8"/><origin xyz="0 0 0.2"/></inertial></link>
<link name="r1"><inertial><mass value="2"/><origin xyz="0.1 0 0"/></inertial></link>
<link name="r2"><inertial><mass value="1.5"/><origin xyz="0.15 0 0"/></inertial></link>
<link name="l1"><inertial><mass value="2"/><origin xyz="-0.1 0 0"/></inertial></link>
<link name="l2"><inertial><mass value="1.5"/><origin xyz="-0.15 0 0"/></inertial></link>
<link name="rm"/><link name="lm"/>
<joint name="t" type="revolute"><parent link="base"/><child link="torso"/>
<origin xyz="0 0 0.5"/><axis xyz="0 1 0"/><limit lower="-1" upper="1"/></joint>
<joint name="r1j" type="revolute"><parent link="torso"/><child link="r1"/>
<origin xyz="0 -0.2 0.4"/><axis xyz="1 0 0"/><limit lower="-2" upper="2"/></joint>
<joint name="r2j" type="revolute"><parent link="r1"/><child link="r2"/>
<origin xyz="0.3 0 0"/><axis xyz="0 0 1"/><limit lower="-2" upper="2"/></joint>
<joint name="rmj" type="fixed"><parent link="r2"/><child link="rm"/><origin xyz="0.3 0 0"/></joint>
<joint name="l1j" type="revolute"><parent link="torso"/><child link="l1"/>
<origin xyz="0 0.2 0.4"/><axis xyz="1 0 0"/><limit lower="-2" upper="2"/></joint>
<joint name="l2j" type="revolute"><parent link="l1"/><child link="l2"/>
<origin xyz="-0.3 0 0"/><axis xyz="0 0 1"/><limit lower="-2" upper="2"/></joint>
<joint name="lmj" type="fixed"><parent link="l2"/><child link="lm"/><origin xyz="-0.3 0 0"/></joint>
</robot>"""


@pytest.fixture(scope="module")
def elastic_tree(tmp_path_factory):
    path = tmp_path_factory.mktemp("masses") / "two.urdf"
    path.write_text(TWO_ARMS)
    tree = cc.load_robot(path, tip_link=["rm", "lm"])
    compliant = tree.with_compliance(lateral=True)
    values = {n: 3e-4 for n in compliant.parameter_names if re.fullmatch(r"c\d+(_[uv])?", n)}
    return compliant.with_deviations(values)


def test_masses_at_their_cad_values_change_nothing(elastic_tree):
    q = cc.poses.uniform(elastic_tree, 30, seed=1)
    with_masses = elastic_tree.with_masses()
    assert [n for n in with_masses.parameter_names if re.fullmatch(r"m\d+", n)] == [
        "m1",
        "m2",
        "m3",
        "m4",
        "m5",
    ]
    assert with_masses.parameters["m1"] == 8.0 and with_masses.parameters["m1_z"] == 0.2
    assert np.abs(with_masses.position(q) - elastic_tree.position(q)).max() < 1e-15
    # a heavier torso bends its own joint further: the parameters are read
    heavier = with_masses.with_deviations({"m1": 4.0})
    assert np.abs(heavier.position(q) - elastic_tree.position(q)).max() > 1e-4


def test_mass_jacobians_against_central_differences(elastic_tree):
    robot = elastic_tree.with_masses()
    q = cc.poses.uniform(robot, 20, seed=2)
    names = [n for n in robot.parameter_names if re.fullmatch(r"(m\d+(_[xyz])?|c\d+(_[uv])?)", n)]
    J, got = robot.position_jacobian(q, names)
    J = J.reshape(len(q), -1, len(got))
    for k, name in enumerate(got):
        h = 1e-6 if name.startswith("m") else 1e-9
        up = robot.with_deviations({name: h}).position(q).reshape(len(q), -1)
        down = robot.with_deviations({name: -h}).position(q).reshape(len(q), -1)
        fd = (up - down) / (2 * h)
        scale = max(np.abs(fd).max(), 1e-12)
        assert np.abs(J[:, :, k] - fd).max() < 1e-6 * scale + 1e-12, name


@pytest.mark.slow  # three fits of a 6R arm with compliance, about a minute
def test_a_mass_the_cad_gets_wrong_is_found_from_what_it_bends():
    """A KR 120-class arm (the report's compliance study) whose last body weighs 150 kg
    where the CAD says 120, its joints' compliances known (the maker's): the CAD's mass
    leaves the fit above the noise; with m6 a parameter it comes back within its standard
    error and the fit reaches the floor. Estimated together with the compliances, the
    mass cannot be told from them at these poses: held, and the fit fails its audit."""
    sigma = 0.02e-3
    rigid = cc.load_robot("kr15_2").with_points([[0.05, 0.02, 0.1]])
    cad = dataclasses.replace(rigid, inertials=INERTIALS)
    nominal = cad.with_compliance([2, 3]).with_deviations({"c2": 1e-6, "c3": 1.5e-6})
    true = nominal.with_masses([6]).with_deviations({"m6": 30.0, "base_x": 1.0})
    q = cc.poses.uniform(true, 200, seed=3)
    meas = cc.simulate(true, q, noise=sigma, seed=4)
    q_new = cc.poses.uniform(true, 200, seed=5)

    def held_out(cal):
        miss = cal.robot.measured_points(q_new) - true.measured_points(q_new)
        return float(np.sqrt(np.mean(miss**2)))

    # a hand the CAD may have wrong by tens of kilograms: the robot's own plausible size
    start = nominal.with_masses([6]).with_plausible(**{"kg": 50.0})
    geometry_and_mass = [n for n in start.parameter_names if n not in ("c2", "c3")]
    cad_fit = cc.identify(nominal, meas, [n for n in geometry_and_mass if n[0] != "m"])
    fit = cc.identify(start, meas, geometry_and_mass)
    assert fit.success, fit.message
    z = (fit.robot.parameters["m6"] - 150.0) / fit.standard_errors["m6"]
    assert abs(z) < 4, (fit.robot.parameters["m6"], fit.standard_errors["m6"])
    assert fit.standard_errors["m6"] < 1.0  # kg: the data do see it
    assert held_out(fit) < 1.5 * sigma < held_out(cad_fit)
    assert not cad_fit.success  # the CAD's mass is a model error, and it says so
    together = cc.identify(start, meas, "all")
    assert "m6" not in together.estimated and together.held_reason("m6")
    assert not together.success


def test_a_robot_file_keeps_the_masses_and_refuses_a_centre_in_millimetres(elastic_tree, tmp_path):
    robot = elastic_tree.with_masses([2]).with_deviations({"m2": 0.5, "m2_x": 0.01})
    cc.save_robot(robot, tmp_path / "r.toml")
    back = cc.load_robot(tmp_path / "r.toml")
    q = cc.poses.uniform(robot, 10, seed=3)
    assert np.abs(back.position(q) - robot.position(q)).max() < 1e-12
    assert back.parameters["m2"] == 2.5 and back.parameters["m2_x"] == pytest.approx(0.11)
    text = (tmp_path / "r.toml").read_text()
    mm = text.replace("m2_x = 0.11", "m2_x = 110.0")
    assert mm != text
    (tmp_path / "mm.toml").write_text(mm)
    with pytest.raises(cc.CalibrationError, match=r"masses.m2_x = 110 m .* in SI \(m\)"):
        cc.load_robot(tmp_path / "mm.toml")
    (tmp_path / "neg.toml").write_text(text.replace("m2 = 2.5", "m2 = -2.5"))
    with pytest.raises(cc.CalibrationError, match=r"masses.m2 = -2.5 kg is negative"):
        cc.load_robot(tmp_path / "neg.toml")
