"""Plausible deviation sizes per robot (`Robot.sizes`, `with_plausible`, ``[plausible]``).

The industrial defaults (2.5 mm, 0.5°; poorly determined past 1 mm, 0.1°) hold, on an arm
whose links are off by a centimetre and whose points carry 1 mm of noise, what the data do
see, and the command then writes nothing. The simulated arm below is humanoid-sized (links
of 0.06 to 0.22 m, a marker on the hand), moves its joints ±45° only (a motion-capture
session), has every DH parameter off by 10 mm or 1 to 2°, and is measured with σ = 1 mm per
coordinate at 300 poses. The truth is known: the held-out error of 300 new poses is
judged against the noise floor √3 σ, independent of casecal's own numbers.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import casecal as cc
from casecal.cli import main
from casecal.data.files import write_csv
from casecal.identification import rank
from casecal.model.parameters import UNITS, checked_sizes, unit

SIGMA = 1e-3
FLOOR = math.sqrt(3) * SIGMA  # RMS of a 3-D point's noise: no model fits held-out data better

ARM_TOML = """\
name = "arm7"
convention = "dh"
length_unit = "mm"
angle_unit = "deg"
[[joints]]
type = "R"
a = 0.0
alpha = -90.0
d = 100.0
limits = [-45.0, 45.0]
[[joints]]
type = "R"
a = 0.0
alpha = 90.0
d = 0.0
limits = [-45.0, 45.0]
[[joints]]
type = "R"
a = 0.0
alpha = 90.0
d = 220.0
limits = [-45.0, 45.0]
[[joints]]
type = "R"
a = 0.0
alpha = -90.0
d = 0.0
limits = [-45.0, 45.0]
[[joints]]
type = "R"
a = 0.0
alpha = -90.0
d = 200.0
limits = [-45.0, 45.0]
[[joints]]
type = "R"
a = 0.0
alpha = 90.0
d = 0.0
limits = [-45.0, 45.0]
[[joints]]
type = "R"
a = 0.0
alpha = 0.0
d = 60.0
limits = [-45.0, 45.0]
[tool]
xyz = [60.0, 20.0, 100.0]  # a marker on the hand
"""

HUMANOID = {"length": 0.01, "angle": math.radians(2)}


def _truth(robot) -> dict:
    """10 mm on every d and a, 1 to 2° on every θ and α, random signs (seed 1)."""
    rng = np.random.default_rng(1)
    out = {}
    for name in robot.parameter_names:
        if name[:-1] in ("theta", "d", "a", "alpha"):
            size = 0.010 if name[0] == "d" or name[:-1] == "a" else math.radians(rng.uniform(1, 2))
            out[name] = float(rng.choice([-1, 1])) * size
    return out


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    """The arm's file, its true deviations, 300 measured poses (CSV) and 300 new ones."""
    folder = tmp_path_factory.mktemp("arm")
    path = folder / "arm7.toml"
    path.write_text(ARM_TOML)
    nominal = cc.load_robot(path)
    truth = _truth(nominal)
    assert len(truth) == 28  # θ, d, a, α of 7 links
    true = nominal.with_deviations(truth)
    meas = cc.simulate(true, cc.poses.uniform(nominal, 300, seed=2), noise=SIGMA, seed=4)
    new = cc.simulate(true, cc.poses.uniform(nominal, 300, seed=3), noise=SIGMA, seed=5)
    csv = folder / "arm7.csv"
    write_csv(csv, meas, nominal)
    return {"path": path, "nominal": nominal, "truth": truth, "meas": meas, "new": new, "csv": csv}


def _held_out(robot, arm) -> float:
    """RMS error (m) of `robot` on the 300 new poses, frames refitted."""
    return cc.validate(robot, arm["new"], arm["nominal"]).after.rms


def test_default_sizes_hold_what_the_data_see(arm):
    """Today's industrial sizes: parameters off by 10 mm are held at nominal for their
    standard errors of a few mm, and most estimates are 'poorly determined'; holding those
    too (what identify -o does before writing) leaves a fit that does not pass."""
    from casecal.identification.usable import hold_poorly_determined

    nominal = arm["nominal"]
    assert nominal.sizes == ()
    cal = cc.identify(nominal, arm["meas"], "all", noise=SIGMA)
    assert cal.success
    assert cal.pruned
    for name in cal.pruned:  # held with a standard error beyond 2.5 mm or 0.5°
        assert "more than any real deviation (2.5 mm)" in cal.pruned[name] or (
            "more than any real deviation (0.5 °)" in cal.pruned[name]
        )
        assert abs(arm["truth"][name]) > UNITS[unit(name)].plausible
    assert len(cal.poorly_determined) >= 5
    refit = hold_poorly_determined(cal, arm["meas"], noise=SIGMA)
    assert not refit.success
    assert _held_out(refit.robot, arm) > 1.25 * FLOOR  # what writing it anyway would give


def test_own_sizes_estimate_them(arm):
    """With 10 mm and 2° the parameters held above are estimated, near their truth, and
    the held-out error is the noise floor's."""
    nominal = arm["nominal"]
    default = cc.identify(nominal, arm["meas"], "all", noise=SIGMA)
    robot = nominal.with_plausible(**HUMANOID)
    cal = cc.identify(robot, arm["meas"], "all", noise=SIGMA)
    assert cal.success
    assert default.pruned and not cal.pruned
    for name in default.pruned:  # estimated now, and as near the truth as its error says
        assert name in cal.estimated and cal.stands_for(name) == name
        error = cal.deviations[name] - arm["truth"][name]
        assert abs(error) < 4 * cal.standard_errors[name], name
    assert _held_out(cal.robot, arm) < 1.1 * FLOOR
    # the sizes travel with the fit and are stated
    assert cal.robot.sizes == robot.sizes
    text = str(cal.summary())
    assert "plausible deviations 10 mm, 2° (default 2.5 mm, 0.5°)" in text
    assert "4 mm, 0.4° poorly determined" in text
    assert "standard error above 4 mm or 0.4°" in text  # the poorly determined note
    # why a parameter is held names the robot's size, not the default
    why = rank._reason("a2", 0.02, 1e-5, 0.01, False, robot.sizes)
    assert "more than any real deviation (10 mm)" in why


def test_identify_writes_with_own_sizes(arm, tmp_path, capsys):
    """The command: with the industrial sizes it writes nothing; with
    --plausible-length-mm 10 --plausible-angle-deg 2 it writes a robot file that keeps
    the sizes and is as good as the noise on new poses."""
    out = tmp_path / "out.toml"
    args = ["identify", str(arm["path"]), str(arm["csv"]), "--parameters", "all", "-o", str(out)]
    assert main(args) == 2
    assert "nothing written" in capsys.readouterr().err
    assert not out.exists()

    assert main([*args, "--plausible-length-mm", "10", "--plausible-angle-deg", "2"]) == 0
    printed = capsys.readouterr().out
    assert "plausible deviations 10 mm, 2°" in printed
    calibrated = cc.load_robot(out)
    assert calibrated.sizes == arm["nominal"].with_plausible(**HUMANOID).sizes
    assert _held_out(calibrated, arm) < 1.1 * FLOOR


def test_robot_file_sizes_and_flag_override(arm, tmp_path, capsys):
    """The file's [plausible] table is used without flags; a flag overrides its unit."""
    path = tmp_path / "arm7.toml"
    path.write_text(ARM_TOML + "[plausible]\nlength_mm = 10.0\nangle_deg = 2.0\n")
    robot = cc.load_robot(path)
    assert robot.sizes == arm["nominal"].with_plausible(**HUMANOID).sizes
    out = tmp_path / "out.toml"
    args = ["identify", str(path), str(arm["csv"]), "--parameters", "all", "-o", str(out)]
    assert main([*args, "--plausible-angle-deg", "3"]) == 0
    assert "plausible deviations 10 mm, 3°" in capsys.readouterr().out
    facts = cc.load_robot(out).unit_facts("theta2")
    assert facts.plausible == pytest.approx(math.radians(3), rel=1e-15)
    assert facts.poorly == pytest.approx(math.radians(0.6), rel=1e-15)


# --- the API ---------------------------------------------------------------------------


def test_with_plausible_api():
    robot = cc.load_robot("puma560")
    assert robot.sizes == () and robot.unit_facts("a2") is UNITS["m"]
    own = robot.with_plausible(length=0.01, angle=math.radians(2))
    assert own.sizes == (("m", 0.01, 0.004), ("rad", math.radians(2), math.radians(2) * 0.2))
    assert own.unit_facts("a2").plausible == 0.01 and own.unit_facts("a2").poorly == 0.004
    assert own.unit_facts("theta3").plausible == math.radians(2)
    # a pair gives the poorly determined bound; other units by name; the rest is kept
    both = own.with_plausible(angle=(0.05, 0.02), **{"rad/(N·m)": 1e-4})
    assert both.unit_facts("alpha1").poorly == 0.02
    assert both.unit_facts("a1").plausible == 0.01
    assert both.unit_facts("c2").plausible == 1e-4
    assert both.unit_facts("c2").poorly == pytest.approx(1e-4 * 5e-7 / 2e-5, rel=1e-15)
    # the defaults again are no sizes: the same robot
    assert own.with_plausible(length=2.5e-3, angle=math.radians(0.5)) == robot
    # kinematics untouched: same structure (kernel cache key), same vector, same FK
    assert own.structure == robot.structure
    assert hash(own.structure) == hash(robot.structure)
    q = cc.poses.uniform(robot, 5, seed=0)
    np.testing.assert_array_equal(own.fk(q), robot.fk(q))
    # variants keep them
    assert own.with_deviations({"a2": 1e-3}).sizes == own.sizes
    hash(own)  # still hashable


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"length": -0.01}, "must be positive"),
        ({"length": 0.0}, "must be positive"),
        ({"angle": math.nan}, "positive finite number"),
        ({"angle": math.inf}, "positive finite number"),
        ({"length": "1cm"}, "positive finite number"),
        ({"length": True}, "positive finite number"),
        ({"length": (0.01, -1.0)}, "poorly determined bound of lengths (m)"),
        ({"length": (1, 2, 3)}, "(plausible, poorly) pair"),
        ({"furlong": 1.0}, "knows no such unit"),
        ({"length": 0.01, "m": 0.02}, "give one"),
    ],
)
def test_with_plausible_refuses(kwargs, needle):
    with pytest.raises(cc.CalibrationError, match="robot 'puma560'") as info:
        cc.load_robot("puma560").with_plausible(**kwargs)
    assert needle in str(info.value)


def test_robot_checks_sizes_given_directly():
    joints = (cc.Joint("R", 0.3, 0.0, 0.0),)
    with pytest.raises(cc.CalibrationError, match="knows no such unit"):
        cc.Robot("r", joints, sizes=(("cm", 1.0, 0.4),))
    with pytest.raises(cc.CalibrationError, match="given twice"):
        checked_sizes((("m", 0.01, 0.004), ("m", 0.02, 0.004)))
    robot = cc.Robot("r", joints, sizes=(("rad", 0.1, 0.02), ("m", 0.01, 0.004)))
    assert [s[0] for s in robot.sizes] == ["m", "rad"]  # one order: equal robots are equal


# --- robot files -----------------------------------------------------------------------


def test_toml_round_trip(tmp_path):
    robot = cc.load_robot("kr16_2").with_plausible(
        length=0.0123, angle=(math.radians(1.7), math.radians(0.3)), **{"rad/m": 0.05}
    )
    path = tmp_path / "kr.toml"
    assert cc.save_robot(robot, path) == []
    back = cc.load_robot(path)
    assert back.sizes == robot.sizes  # to the last bit: written in SI
    assert back == robot
    text = path.read_text()
    assert "[plausible]" in text and "# 12.3 mm" in text and "# 1.7°" in text
    # a robot without sizes writes no table
    assert "plausible" not in cc.robot_to_toml(cc.load_robot("kr16_2"))


def test_toml_in_mm_and_degrees(write_toml):
    head = 'name = "one"\nconvention = "dh"\n'
    head += '[[joints]]\ntype = "R"\na = 0.3\nalpha = 0.0\nd = 0.0\n'
    robot = cc.load_robot(
        write_toml(
            head + "[plausible]\nlength_mm = 8.0\nangle_deg = 1.5\n"
            "[plausible.poorly]\nangle_deg = 0.5\n"
        )
    )
    assert robot.unit_facts("a1").plausible == pytest.approx(8e-3, rel=1e-15)
    assert robot.unit_facts("a1").poorly == pytest.approx(8e-3 * 0.4, rel=1e-15)
    assert robot.unit_facts("theta1").plausible == pytest.approx(math.radians(1.5), rel=1e-15)
    assert robot.unit_facts("theta1").poorly == pytest.approx(math.radians(0.5), rel=1e-15)
    # a poorly determined bound alone keeps the plausible default
    alone = cc.load_robot(write_toml(head + "[plausible.poorly]\nlength_m = 0.002\n", "b.toml"))
    assert alone.sizes == (("m", 2.5e-3, 0.002),)


@pytest.mark.parametrize(
    ("table", "needle"),
    [
        ("plausible = 3\n", "plausible must be a table"),
        ("[plausible]\nlength_cm = 1.0\n", "unknown key 'length_cm' at [plausible]"),
        ("[plausible]\nlength_mm = 10.0\nlength_m = 0.01\n", "twice"),
        ("[plausible]\nangle_deg = -2.0\n", "must be positive"),
        ('[plausible]\nangle_deg = "2"\n', "plausible.angle_deg = '2' is not a number"),
        ("[plausible]\npoorly = 1.0\n", "plausible.poorly must be a table"),
        ("[plausible.poorly]\nfoo = 1.0\n", "unknown key 'foo' at [plausible.poorly]"),
    ],
)
def test_toml_refuses(write_toml, table, needle):
    top = 'name = "one"\nconvention = "dh"\n'
    joints = '[[joints]]\ntype = "R"\na = 0.3\nalpha = 0.0\nd = 0.0\n'
    text = top + joints + table if table.startswith("[") else top + table + joints
    with pytest.raises(cc.CalibrationError) as info:
        cc.load_robot(write_toml(text))
    assert needle in str(info.value)


def test_urdf_export_says_the_sizes_are_not_kept(tmp_path):
    robot = cc.load_robot("ur5e").with_plausible(length=0.01)
    notes = cc.save_robot(robot, tmp_path / "ur5e.urdf")
    assert any("sizes of a real deviation" in n and "not written" in n for n in notes)
    assert cc.load_robot(tmp_path / "ur5e.urdf").sizes == ()
    assert cc.save_robot(robot.with_plausible(length=2.5e-3), tmp_path / "plain.urdf") == []


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf", "ten"])
def test_cli_refuses_bad_sizes(value, capsys):
    with pytest.raises(SystemExit) as info:
        main(["identify", "puma560", "m.csv", "--plausible-length-mm", value])
    assert info.value.code == 2
    assert "is not a size" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"length": 10}, "millimetres in metres"),
        ({"angle": 2}, "degrees in radians"),
        ({"length": (0.001, 0.05)}, "exceeds its plausible deviation"),
    ],
)
def test_sizes_that_are_a_unit_slip_are_refused(kwargs, needle):
    """10 m or 2 rad as a plausible deviation is mm or degrees given as SI: refused, as is
    a poorly determined bound larger than the deviation (review of issue 21)."""
    with pytest.raises(cc.CalibrationError, match=needle):
        cc.load_robot("puma560").with_plausible(**kwargs)
