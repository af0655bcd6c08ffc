"""Units checked at the door (issue 19): a unit slip in a measurement file or in
Measurements built in code never ends in a success, and a legitimate file is not refused.

The slips are made the way a user makes them: a CSV simulated from a true robot, then one
kind of column rewritten in another unit. Before the door existed, metres in x_mm columns
fitted a PUMA 560 with a2 = 0.43 mm to the rounding floor, exit 0, every audit check ok.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from random_robots import CASES as cases

import casecal as cc
from casecal.cli import main
from casecal.errors import CalibrationWarning

DEG = math.pi / 180
POSITIONS = ("x_mm", "y_mm", "z_mm")


@pytest.fixture(scope="module")
def puma():
    """The PUMA 560 of case 1: 120 uniform poses, a few DH deviations, no noise."""
    robot = cc.load_robot("puma560")
    true = robot.with_deviations({"a2": 2e-4, "d3": -1e-4, "theta2": 3e-4})
    q = cc.poses.uniform(robot, 120, seed=0)
    return robot, true, q, cc.simulate(true, q)


@pytest.fixture(scope="module")
def puma_seed():
    """`casecal simulate puma560 --poses 120 --noise 0.01mm` (the default, the paper's
    schedule: every joint at 0, 1, 2, … degrees together, one curve through the space)."""
    robot = cc.load_robot("puma560")
    true = robot.with_deviations({"a2": 2e-4, "d3": -1e-4, "theta2": 3e-4})
    q = cc.poses.seed_schedule(robot, 120)
    return robot, true, q, cc.simulate(true, q, noise=1e-5, seed=0)


def _csv(tmp_path, robot, meas, change=None, name="m.csv"):
    """`meas` written as the CLI's CSV, with `change(df)` applied to the columns."""
    path = tmp_path / name
    cc.write_csv(path, meas, robot)
    if change is not None:
        df = pd.read_csv(path)
        change(df)
        df.to_csv(path, index=False, float_format="%.17g")
    return path


def _divide_positions(by):
    def change(df):
        for c in df.columns:
            if c.endswith(POSITIONS):
                df[c] = df[c] / by

    return change


def _degrees_as_radians(df):
    for c in df.columns:
        if c.endswith("_deg"):
            df[c] = np.deg2rad(df[c])


# ---- case 1 through the command line ----------------------------------------------------


def test_metres_in_mm_columns_refused_by_the_cli(tmp_path, capsys, puma):
    robot, _, _, meas = puma
    csv = _csv(tmp_path, robot, meas, _divide_positions(1000))
    out = tmp_path / "cal.toml"
    code = main(["identify", "puma560", str(csv), "--parameters", "all", "-o", str(out)])
    err = capsys.readouterr().err
    # before: exit 0, "converged: residuals are at the rounding floor", a2 = 0.435 mm written
    assert code == 2, err
    assert not out.exists()
    assert "x_mm, y_mm, z_mm in metres" in err
    assert "1/1000" in err


def test_radians_in_degree_columns_name_the_unit_not_max_iterations(tmp_path, capsys, puma):
    robot, _, _, meas = puma
    csv = _csv(tmp_path, robot, meas, _degrees_as_radians)
    out = tmp_path / "cal.toml"
    code = main(["identify", "puma560", str(csv), "--parameters", "all", "-o", str(out)])
    err = capsys.readouterr().err
    # before: "the fit stopped before the minimum (... more iterations with --max-iterations"
    assert code == 2 and not out.exists()
    assert "--max-iterations" not in err
    assert "q1_deg" in err and "radians" in err and "degrees" in err


@pytest.mark.parametrize(
    ("change", "words"),
    [
        (_divide_positions(1000), "x_mm, y_mm, z_mm in metres"),
        (_degrees_as_radians, "look like radians"),
    ],
)
def test_slips_in_the_default_schedule_refused_by_the_cli(
    tmp_path, capsys, puma_seed, change, words
):
    """The lockstep schedule moves the tool along one curve, which a rotating tool
    offset nearly explains; the door must still tell a 1000× smaller copy apart."""
    robot, _, _, meas = puma_seed
    csv = _csv(tmp_path, robot, meas, change)
    out = tmp_path / "cal.toml"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the schedule leaves joint 3's limits
        code = main(["identify", "puma560", str(csv), "--parameters", "all", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and not out.exists(), err
    assert words in err and "--max-iterations" not in err


def test_inches_in_mm_columns_refused(tmp_path, capsys, puma):
    robot, _, _, meas = puma
    csv = _csv(tmp_path, robot, meas, _divide_positions(25.4))
    with pytest.raises(cc.CalibrationError, match=r"1/25\.4 .*in inches\?"):
        cc.read_csv(csv, robot)
    code = main(["identify", "puma560", str(csv), "-o", str(tmp_path / "cal.toml")])
    assert code == 2 and "inches" in capsys.readouterr().err


def test_micrometres_in_mm_columns_refused(tmp_path, puma):
    robot, _, _, meas = puma
    csv = _csv(tmp_path, robot, meas, _divide_positions(1e-3))
    with pytest.raises(cc.CalibrationError, match="1000 times what the robot reaches"):
        cc.read_csv(csv, robot)


# ---- the API: Measurements built in code ---------------------------------------------------


@pytest.mark.parametrize(
    ("factor", "words"),
    [(1e3, "in millimetres"), (1e-3, "metres divided by 1000"), (1 / 25.4, "unit of the")],
)
def test_identify_refuses_positions_in_another_unit(puma, factor, words):
    robot, _, q, meas = puma
    slipped = cc.Measurements(q, meas.positions * factor, 0.0)
    # before: success for all three, the robot scaled to match
    with pytest.raises(cc.CalibrationError, match=words):
        cc.identify(robot, slipped, "all")


def test_identify_refuses_radians_converted_twice(puma):
    robot, _, q, meas = puma
    with pytest.raises(cc.CalibrationError, match="deg2rad"):
        cc.identify(robot, cc.Measurements(np.deg2rad(q), meas.positions, 0.0), "all")


def test_a_fit_that_shrinks_the_robot_fails_and_names_the_unit(puma, monkeypatch):
    """The path behind the door: with every length free, a cloud 1000 times too small is
    fitted exactly by a robot 1000 times smaller, so the residual, noise and prediction
    checks all pass; the size check must not."""
    import casecal.identification.fit as fit

    monkeypatch.setattr(fit, "door", lambda *a: None, raising=False)
    robot, _, q, meas = puma
    cal = cc.identify(robot, cc.Measurements(q, meas.positions / 1000, 0.0), "all")
    # independent of the audit: the fitted robot really is 1000 times smaller (distances
    # between its tool points at two far-apart poses against the nominal's)
    q2 = np.array([[0.0, 0.0, 0.0, 0, 0, 0], [1.0, -0.5, 0.8, 0, 0, 0]])
    fitted, nominal = cal.robot.position(q2), robot.position(q2)
    shrink = np.linalg.norm(fitted[1] - fitted[0]) / np.linalg.norm(nominal[1] - nominal[0])
    assert shrink == pytest.approx(1e-3, rel=0.05)
    assert not cal.success  # before: status 4, "residuals are at the rounding floor"
    assert "robot keeps its size" in cal.message
    assert "x_mm, y_mm, z_mm in metres" in cal.message


def test_an_honest_fit_keeps_the_robot_size(puma):
    robot, true, _, meas = puma
    cal = cc.identify(robot, meas, "all")
    assert cal.success, cal.message
    check = next(c for c in cal.audit.checks if c.name == "robot keeps its size")
    assert check.passed
    held_out = cc.poses.uniform(robot, 50, seed=9)
    assert np.abs(cal.robot.position(held_out) - true.position(held_out)).max() < 1e-8


# ---- legitimate files are not refused -----------------------------------------------------


def _no_unit_warning(caught) -> None:
    units = [w for w in caught if issubclass(w.category, CalibrationWarning)]
    assert not units, [str(w.message) for w in units]


def test_only_the_wrist_moving_is_not_refused(tmp_path):
    """The arm stands still, the wrist turns a tool of 120 mm the robot file does not
    have: the nominal points do not move at all, the measured ones sweep a sphere."""
    robot = cc.load_robot("puma560")
    true = robot.with_deviations({"tool_z": 0.12, "tool_x": 0.03, "base_x": 2.0})
    rng = np.random.default_rng(4)
    q = np.zeros((60, 6))
    q[:, :3] = [0.3, 0.6, -0.9]
    q[:, 3:] = rng.uniform(-60, 60, size=(60, 3)) * DEG
    meas = cc.simulate(true, q, noise=1e-5, seed=1)
    csv = _csv(tmp_path, robot, meas)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        back = cc.read_csv(csv, robot)
        cal = cc.identify(robot, back, ["tool_x", "tool_y", "tool_z", "base_x", "base_y", "base_z"])
    _no_unit_warning(caught)
    assert cal.success, cal.message
    assert cal.deviations["tool_z"] == pytest.approx(0.12, abs=1e-4)


def test_poses_in_a_small_region_in_degrees_are_not_taken_for_radians(tmp_path):
    """Every joint within ±3° of zero: the values all lie within ±π, as radians in degree
    columns would, but the measured points fit them as degrees."""
    robot = cc.load_robot("puma560").with_deviations({"tool_z": 0.1})
    true = robot.with_deviations({"a2": 3e-4, "d4": -2e-4, "base_x": 1.5, "base_rz": 0.4})
    q = np.random.default_rng(2).uniform(-3, 3, size=(80, 6)) * DEG
    assert np.abs(np.rad2deg(q)).max() < 3.2
    meas = cc.simulate(true, q, noise=1e-5, seed=3)
    csv = _csv(tmp_path, robot, meas)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        back = cc.read_csv(csv, robot)
        cc.identify(robot, back, ["base_*"])
    _no_unit_warning(caught)


def test_a_wrist_only_file_in_metres_is_still_caught_by_the_fit(tmp_path):
    """Where the door cannot judge (the nominal points barely move), the unit slip does
    not end in success either."""
    robot = cc.load_robot("puma560").with_deviations({"tool_z": 0.15})
    rng = np.random.default_rng(5)
    q = np.zeros((60, 6))
    q[:, :3] = [0.3, 0.6, -0.9]
    q[:, 3:] = rng.uniform(-60, 60, size=(60, 3)) * DEG
    meas = cc.simulate(robot.with_deviations({"a2": 3e-4}), q)
    csv = _csv(tmp_path, robot, meas, _divide_positions(1000))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            cal = cc.identify(robot, cc.read_csv(csv, robot), "all")
        except cc.CalibrationError:
            return
    assert not cal.success, cal.message


# ---- property: random arms, every slip fails, no unscaled file is refused ---------------


SLIPS = {
    "metres in mm columns": _divide_positions(1000),
    "micrometres in mm columns": _divide_positions(1e-3),
    "inches in mm columns": _divide_positions(25.4),
    "positions x25.4": _divide_positions(1 / 25.4),
    "radians in deg columns": _degrees_as_radians,
}


def _ends_in_success(robot, path) -> tuple[bool, str]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            cal = cc.identify(robot, cc.read_csv(path, robot), "all")
        except cc.CalibrationError as exc:
            return False, f"refused: {exc}"
    return cal.success, cal.message


def check_case(case, tmp_path) -> None:
    meas = cc.simulate(case.true, case.q_fit, noise=case.sigma, seed=7)
    robot = case.nominal
    for name, change in SLIPS.items():
        if name.startswith("radians") and "R" not in robot.joint_types:
            continue
        path = _csv(tmp_path, robot, meas, change, name="slip.csv")
        success, message = _ends_in_success(robot, path)
        assert not success, f"{name}: success with {robot.joint_types}: {message}"
    path = _csv(tmp_path, robot, meas, name="clean.csv")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        back = cc.read_csv(path, robot)
        cal = cc.identify(robot, back, "all")
    _no_unit_warning(caught)
    size = next(c for c in cal.audit.checks if c.name == "robot keeps its size")
    assert size.passed, size.text


SETTINGS = {
    "deadline": None,
    "derandomize": True,
    "suppress_health_check": [
        HealthCheck.too_slow,
        HealthCheck.data_too_large,
        HealthCheck.function_scoped_fixture,
    ],
}


@settings(max_examples=6, **SETTINGS)
@given(case=cases)
def test_random_arms_never_succeed_with_a_unit_slip(case, tmp_path):
    check_case(case, tmp_path)


@pytest.mark.slow
@settings(max_examples=60, **SETTINGS)
@given(case=cases)
def test_random_arms_never_succeed_with_a_unit_slip_many(case, tmp_path):
    check_case(case, tmp_path)


# ---- case 13: messages a shell user can act on -----------------------------------------------


def test_a_missing_robot_file_is_a_missing_file_not_an_unknown_robot(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "myrobot.urdf").write_text("<robot name='x'/>")
    (tmp_path / "arm_v2.toml").write_text("")
    with pytest.raises(cc.CalibrationError, match=r"no file 'arm\.toml'.*arm_v2\.toml"):
        cc.load_robot("arm.toml")
    with pytest.raises(cc.CalibrationError, match=r"no file 'myrobto\.urdf'.*myrobot\.urdf"):
        cc.load_robot("myrobto.urdf")
    # before: "unknown robot 'ARM.TOML'; catalog robots are: …"
    with pytest.raises(cc.CalibrationError, match=r"no file 'ARM\.TOML'"):
        cc.load_robot("ARM.TOML")
    with pytest.raises(cc.CalibrationError, match=r"no file 'arm\.yml'"):
        cc.load_robot("arm.yml")


def test_the_cli_says_no_file_for_a_mistyped_path(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "m.csv").write_text("q1,x,y,z\n0,0,0,0\n")
    assert main(["show", "arm.toml"]) == 2
    assert "no file 'arm.toml'" in capsys.readouterr().err
    assert main(["identify", "myrobto.urdf", "m.csv"]) == 2
    err = capsys.readouterr().err
    assert "no file 'myrobto.urdf'" in err and "unknown robot" not in err


def test_an_unknown_name_suggests_the_close_ones():
    with pytest.raises(cc.CalibrationError, match="did you mean puma560"):
        cc.load_robot("puma650")


def test_urdf_options_on_a_toml_robot_name_the_flag_and_the_keyword():
    with pytest.raises(cc.CalibrationError) as info:
        cc.load_robot("puma560", tip_link="tool0")
    message = str(info.value)
    # before: "base_link=, tip_link= and packages= apply to URDF files only"
    assert "--tip-link" in message and "tip_link=" in message
    assert "packages" not in message and "base_link" not in message


def test_urdf_chain_messages_name_the_cli_flags(tmp_path):
    two_roots = """<robot name="y">
      <link name="a"/><link name="b"/><link name="c"/><link name="d"/>
      <joint name="j1" type="continuous"><parent link="a"/><child link="b"/></joint>
      <joint name="j2" type="continuous"><parent link="c"/><child link="d"/></joint>
    </robot>"""
    (tmp_path / "y.urdf").write_text(two_roots)
    with pytest.raises(cc.CalibrationError, match=r"base_link=.*--base-link"):
        cc.load_robot(tmp_path / "y.urdf")
    two_tips = """<robot name="z">
      <link name="b"/><link name="l"/><link name="r"/>
      <joint name="jl" type="continuous"><parent link="b"/><child link="l"/></joint>
      <joint name="jr" type="continuous"><parent link="b"/><child link="r"/></joint>
    </robot>"""
    (tmp_path / "z.urdf").write_text(two_tips)
    with pytest.raises(cc.CalibrationError, match=r"tip_link= one of l, r.*--tip-link"):
        cc.load_robot(tmp_path / "z.urdf")


def test_degrees_in_rad_columns_refused(tmp_path, puma):
    """A column named for radians holding degrees (the bare q1 column was refused so
    before; q1_rad only warned that the joint is outside its limits)."""
    robot, _, _, meas = puma

    def rename(df):
        df.columns = [c.replace("_deg", "_rad") if c[0] == "q" else c for c in df.columns]

    csv = _csv(tmp_path, robot, meas, rename)
    with pytest.raises(cc.CalibrationError, match=r"'q\d_rad' \(radians\).*name it q\d_deg"):
        cc.read_csv(csv, robot)


def test_similarity_recovers_a_known_scale_rotation_and_shift():
    """The door's comparison against a transform made by hand (scipy's rotation)."""
    from scipy.spatial.transform import Rotation

    from casecal.data.clouds import rigid_rms, similarity

    rng = np.random.default_rng(0)
    a = rng.normal(size=(50, 3))
    R = Rotation.from_rotvec([0.3, -1.2, 2.0]).as_matrix()
    for scale in (1e-3, 1 / 25.4, 1.0, 1e3):
        b = scale * a @ R.T + [4.0, -2.0, 7.0]
        fit = similarity(a, b)
        assert fit.scale == pytest.approx(scale, rel=1e-12)
        assert fit.shape_error < 1e-9
    b = a @ R.T + 0.01 * rng.normal(size=a.shape)
    # the best rigid fit leaves about the noise: 0.01 per coordinate, 6 of 150 dof used
    assert rigid_rms(a, b) == pytest.approx(0.01 * np.sqrt(3 * (1 - 6 / 150)), rel=0.2)
    assert rigid_rms(a, a @ R.T * 2) > 0.5  # a rigid fit cannot rescale


# ---- distances between poses (ball bar): the same door -------------------------------------


@pytest.fixture(scope="module")
def ball_bar():
    from casecal.identification.distances import random_pairs, simulate_distances

    robot = cc.load_robot("puma560")
    true = robot.with_deviations({"a2": 2e-4, "d3": -1e-4})
    q = cc.poses.uniform(robot, 80, seed=0)
    return robot, simulate_distances(true, q, random_pairs(80, 300, seed=1))


def test_distances_in_inches_refused_through_the_cli(tmp_path, capsys, ball_bar):
    """Before: 'converged: residuals are at the rounding floor', exit 0, a robot 25.4
    times smaller written."""
    from casecal.identification.distances import write_distance_csv

    robot, meas = ball_bar
    poses = cc.Measurements(meas.q, np.zeros((len(meas.q), 3)), 0.0)
    cc.write_csv(tmp_path / "poses.csv", poses, robot)
    write_distance_csv(tmp_path / "pairs.csv", meas)
    df = pd.read_csv(tmp_path / "pairs.csv")
    df["distance_mm"] = df["distance_mm"] / 25.4
    df.to_csv(tmp_path / "pairs.csv", index=False, float_format="%.17g")
    out = tmp_path / "cal.toml"
    argv = ["identify", "puma560", str(tmp_path / "poses.csv"), "--pairs"]
    code = main([*argv, str(tmp_path / "pairs.csv"), "--parameters", "all", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and not out.exists(), err
    assert "distance_mm values in inches" in err


@pytest.mark.parametrize(("factor", "words"), [(1e-3, "in metres"), (1e3, "micrometres")])
def test_distances_in_another_unit_refused(ball_bar, factor, words):
    from casecal.identification.distances import DistanceMeasurements, identify_distances

    robot, meas = ball_bar
    assert identify_distances(robot, meas, "all").success
    slipped = DistanceMeasurements(meas.q, meas.pairs, meas.distances * factor, 0.0)
    with pytest.raises(cc.CalibrationError, match=words):
        identify_distances(robot, slipped, "all")
