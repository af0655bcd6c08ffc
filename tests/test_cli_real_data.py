"""The engineer's path from the shell: identify with holdout, write, validate."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

import casecal as cc
from casecal.cli import main
from casecal.data.files import write_csv

EXAMPLE = Path(__file__).parents[1] / "examples" / "tracker_session.csv"


def test_example_session_identify_holdout_and_validate(tmp_path, capsys):
    out, dev = tmp_path / "calibrated.toml", tmp_path / "deviations.json"
    code = main(
        [
            "identify",
            "puma560",
            str(EXAMPLE),
            "--parameters",
            "all",
            "--method",
            "gauss-newton",
            "--holdout",
            "0.25",
            "-o",
            str(out),
            "--deviations-out",
            str(dev),
        ]
    )
    text = capsys.readouterr().out
    assert code == 0
    assert "Validation on 10 held-out poses" in text
    before, after = (float(m) for m in re.findall(r"^(?:before|after)\s+([\d.]+)", text, re.M))
    assert after < 0.05 < before  # mm: the DH errors are gone, the noise is 0.02 mm
    calibrated = cc.load_robot(out)
    assert calibrated.calibrated_from == "puma560" and len(calibrated.points) == 2
    # strict JSON (no NaN, which other languages' parsers reject): held ones are null
    data = json.loads(dev.read_text(), parse_constant=lambda c: pytest.fail(f"JSON has {c}"))
    assert data["parameters"]["a2"]["unit"] == "m" and data["parameters"]["a2"]["estimated"]
    held = [v for v in data["parameters"].values() if not v["estimated"]]
    assert held and all(v["standard_error"] is None for v in held)

    # a second session with the instrument elsewhere: validate refits only the frames
    true = (
        cc.load_robot("puma560")
        .with_deviations({"a2": 0.0, "base_x": -1.0, "base_rz": 0.3})
        .with_points(calibrated.points)
    )
    fresh = cc.simulate(true, cc.poses.uniform(true, 30, seed=1), noise=0.02e-3, seed=2)
    csv = tmp_path / "holdout.csv"
    write_csv(csv, fresh, true)
    assert main(["validate", str(out), str(csv)]) == 0
    assert "before" in capsys.readouterr().out


def test_validate_needs_to_know_the_nominal(tmp_path, capsys):
    robot = cc.load_robot("rr")
    path = tmp_path / "rr.toml"
    path.write_text(cc.robot_to_toml(robot))
    csv = tmp_path / "m.csv"
    write_csv(csv, cc.simulate(robot, np.array([[0.1, 0.2], [0.3, 0.1]])), robot)
    assert main(["validate", str(path), str(csv)]) == 2
    assert "--nominal" in capsys.readouterr().err


def test_joint_values_outside_limits_warn_in_one_line(tmp_path, capsys):
    robot = cc.load_robot("scorbot")
    q = cc.poses.seed_schedule(robot, 30)  # the paper's schedule leaves joint 3's range
    csv = tmp_path / "m.csv"
    write_csv(csv, cc.simulate(robot, q), robot)
    assert main(["identify", "scorbot", str(csv)]) == 0
    err = capsys.readouterr().err
    warnings_ = [line for line in err.splitlines() if line.startswith("casecal: warning:")]
    assert len(warnings_) == 1 and "joint 3 is outside its limits" in warnings_[0]


def test_strict_refuses_blind_parameters(tmp_path, capsys):
    robot = cc.load_robot("scorbot")
    csv, out = tmp_path / "m.csv", tmp_path / "c.toml"
    write_csv(csv, cc.simulate(robot, cc.poses.uniform(robot, 30, seed=0)), robot)
    assert main(["identify", "scorbot", str(csv), "--strict", "-o", str(out)]) == 2
    assert "theta5" in capsys.readouterr().err and not out.exists()
    assert main(["identify", "scorbot", str(csv), "--strict", "--parameters", "theta1,a2"]) == 0
