"""casecal simulate | identify | observability, and the measurement CSV files between them."""

from __future__ import annotations

import numpy as np
import pytest

import casecal as cc
from casecal.cli import main, parse_length
from casecal.data.files import read_csv, write_csv
from casecal.model.catalog import load_deviations

DEVIATIONS = """\
length_unit = "mm"
angle_unit = "deg"
[deviations]
theta1 = 0.01
theta2 = -0.005
theta3 = 0.0075
theta4 = -0.0085
a1 = 0.15
a2 = -0.2
a3 = 0.125
d1 = -0.175
d5 = 0.25
"""


def test_csv_round_trip(tmp_path):
    robot = cc.load_robot("scara")  # has a prismatic joint: q3 in mm
    q = cc.poses.uniform(robot, 20, seed=0)
    meas = cc.simulate(robot, q, noise=0.02e-3, seed=1)
    path = tmp_path / "m.csv"
    write_csv(path, meas, robot)
    header = path.read_text().splitlines()[0]
    assert header == "q1_deg,q2_deg,q3_mm,q4_deg,x_mm,y_mm,z_mm,sigma_mm"
    back = read_csv(path, robot)
    np.testing.assert_allclose(back.q, meas.q, rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(back.positions, meas.positions, rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(back.sigma, meas.sigma, rtol=1e-15)


def test_csv_in_si_units_and_extra_columns(tmp_path):
    robot = cc.load_robot("rr")
    path = tmp_path / "si.csv"
    path.write_text("pose,q1,q2,x,y,z,comment\n1,0.1,0.2,1.9,0.3,0.0,first\n2,0.3,0.1,1.8,0.6,0,\n")
    meas = read_csv(path, robot)
    np.testing.assert_array_equal(meas.q, [[0.1, 0.2], [0.3, 0.1]])
    np.testing.assert_array_equal(meas.positions[:, 0], [1.9, 1.8])
    assert np.all(meas.sigma == 0)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("q1,q2,x,y\n0,0,1,1\n", "missing column for z"),
        ("q1,q2,x,y,z,x_mm\n0,0,1,1,1,1\n", "both give x"),
        ("q1,q2,x,y,z\n0,nan,1,1,1\n", "row 2, column 'q2'"),
        ("q1,q2,x,y,z\n0,abc,1,1,1\n", "not a finite number"),
        ("q1,q2,x,y,z\n", "no rows"),
        ("", "empty"),
        ("q1,q2,q3,x,y,z\n0,0,0,1,1,1\n", "has 2 joints"),
        ("q1_mm,q2,x,y,z\n0,0,1,1,1\n", "wrong unit"),
        ("q1,q2,x,y,z,x\n0,0,1,1,1,1\n", "appears twice"),
    ],
)
def test_bad_csv_is_explained(tmp_path, text, needle):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(cc.CalibrationError, match=r"bad\.csv") as info:
        read_csv(path, cc.load_robot("rr"))
    assert needle in str(info.value)


def test_parse_length():
    assert parse_length("0.01mm") == pytest.approx(1e-5)
    assert parse_length("10um") == pytest.approx(1e-5)
    assert parse_length("1e-5m") == pytest.approx(1e-5)
    assert parse_length("0.02") == pytest.approx(2e-5)  # bare numbers are mm
    with pytest.raises(cc.CalibrationError):
        parse_length("fast")


def test_simulate_identify_round_trip(tmp_path, capsys):
    dev = tmp_path / "dev.toml"
    dev.write_text(DEVIATIONS)
    meas, out = tmp_path / "meas.csv", tmp_path / "calibrated.toml"
    assert (
        main(["simulate", "scorbot", "--poses", "100", "--deviations", str(dev), "-o", str(meas)])
        == 0
    )
    assert (
        main(
            [
                "identify",
                "scorbot",
                str(meas),
                "--method",
                "gauss-newton",
                "--parameters",
                "theta*,a*,d*",
                "--truth",
                str(dev),
                "-o",
                str(out),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "d2 + d3 + d4" in text and "theta5" in text and "held at nominal" in text
    calibrated = cc.load_robot(out)
    truth = cc.load_robot("scorbot").with_deviations(load_deviations(dev))
    q = cc.poses.uniform(truth, 50, seed=3)
    # the calibrated model reproduces the true robot's positions, not just the fitted ones
    np.testing.assert_allclose(calibrated.position(q), truth.position(q), atol=1e-12)


def test_observability_command(capsys):
    assert main(["observability", "scara", "--poses", "50"]) == 0
    out = capsys.readouterr().out
    assert "theta4" in out and "d1 + d2 - d3 - d4" in out and "O1" in out


@pytest.mark.parametrize(
    "argv",
    [
        ["simulate", "scorbot", "--poses", "0", "-o", "{tmp}/x.csv"],
        ["simulate", "scorbot", "--noise", "loud", "-o", "{tmp}/x.csv"],
        ["simulate", "scorbot", "--deviations", "{tmp}/none.toml", "-o", "{tmp}/x.csv"],
        ["identify", "scorbot", "{tmp}/none.csv", "-o", "{tmp}/x.toml"],
        ["identify", "nosuch", "{tmp}/none.csv", "-o", "{tmp}/x.toml"],
        ["observability", "scorbot", "--parameters", "gamma*"],
    ],
)
def test_cli_user_errors_exit_2_and_write_nothing(tmp_path, capsys, argv):
    argv = [a.format(tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("casecal: error:") and err.count("\n") == 1
    assert not any(p.name.startswith("x.") for p in tmp_path.iterdir())
