"""Issue 20 finding 5: a catalog name and a path are never confused.

An argument with no slash and no suffix is a catalog name only: a file or folder of that
name in the working folder neither shadows nor breaks it. A slash or a suffix makes a path;
so does a `pathlib.Path` in Python.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import casecal as cc
from casecal.cli import main
from casecal.model.catalog import nominal_of

IMPOSTOR = """name = "impostor"
convention = "dh"
[[joints]]
type = "R"
a = 0.5
alpha = 0.0
d = 0.0
"""


def _catalog(name: str) -> cc.Robot:
    """The catalog robot read by its file's path, so that no name resolution is involved."""
    folder = Path(cc.__file__).parent / "model" / "robots"
    return cc.load_robot(folder / f"{name}.toml")


def _same(a: cc.Robot, b: cc.Robot) -> bool:
    return a.name == b.name and a.parameters == b.parameters


def test_a_folder_named_like_a_catalog_robot_does_not_break_it(tmp_path, monkeypatch, capsys):
    # before: "robot file 'puma560' is a folder; give a file", exit 2
    monkeypatch.chdir(tmp_path)
    (tmp_path / "puma560").mkdir()  # data kept per robot
    assert main(["show", "puma560"]) == 0
    out, err = capsys.readouterr()
    assert out.startswith("puma560:") and err == ""
    assert _same(cc.load_robot("puma560"), _catalog("puma560"))


def test_a_file_named_like_a_catalog_robot_is_not_used_silently(tmp_path, monkeypatch, capsys):
    # before: the local file 'rr' (a one-joint robot 'impostor') was shown instead
    monkeypatch.chdir(tmp_path)
    (tmp_path / "rr").write_text(IMPOSTOR)
    assert main(["show", "rr"]) == 0
    out, err = capsys.readouterr()
    assert out.startswith("rr:") and "impostor" not in out
    assert "./rr" in err and len(err.strip().splitlines()) == 1, err  # says how to use the file
    assert _same(cc.load_robot("rr"), _catalog("rr"))
    # the user says which: a slash makes it the file
    assert main(["show", "./rr"]) == 0
    assert capsys.readouterr().out.startswith("impostor")


def test_a_suffixless_file_that_is_no_catalog_robot_says_how_to_use_it(
    tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "arm").write_text(IMPOSTOR)
    assert main(["show", "arm"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("casecal: error: ") and len(err.strip().splitlines()) == 1
    assert "no catalog robot 'arm'" in err and "./arm" in err, err
    with pytest.raises(cc.CalibrationError, match=r"no catalog robot 'arm'.*\./arm"):
        cc.load_robot("arm")
    assert cc.load_robot("./arm").name == "impostor"


def test_a_path_object_is_a_path(tmp_path, monkeypatch):
    """`load_robot(Path("rr"))`: the caller said it is a path."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(cc.CalibrationError, match=r"load_robot\('rr'\)"):
        cc.load_robot(Path("rr"))  # no such file: the message says how to get the catalog's
    (tmp_path / "rr").write_text(IMPOSTOR)
    assert cc.load_robot(Path("rr")).name == "impostor"
    assert cc.load_robot(tmp_path / "rr").name == "impostor"


def test_the_report_studies_robots_ignore_local_namesakes(tmp_path, monkeypatch):
    # before: `casecal report -o r` made a folder 'r' and every study loading 'r' failed;
    # a file named like a catalog robot was used by the studies instead of the catalog's
    from casecal.report import studies_compliance

    monkeypatch.chdir(tmp_path)
    for i, name in enumerate(cc.robots()):
        if i % 2:
            (tmp_path / name).mkdir()
        else:
            (tmp_path / name).write_text(IMPOSTOR)
    for name in cc.robots():
        assert _same(cc.load_robot(name), _catalog(name)), name
    rigid = studies_compliance._robots()["rigid"]
    assert rigid.name == "kr15_2" and len(rigid.joints) == 6


def test_calibrated_from_a_catalog_name_is_not_a_file_beside(tmp_path):
    # before: calibrated_from = "rr" beside a file 'rr' loaded that file as the nominal
    (tmp_path / "rr").write_text(IMPOSTOR)
    text = cc.robot_to_toml(_catalog("rr")).replace('name = "rr"', 'name = "cal"', 1)
    (tmp_path / "cal.toml").write_text('calibrated_from = "rr"\n' + text)
    nominal = nominal_of(cc.load_robot(tmp_path / "cal.toml"))
    assert _same(nominal, _catalog("rr"))


def test_identify_records_a_suffixless_file_so_that_it_reads_back(tmp_path, monkeypatch):
    """A nominal given as ./arm is recorded as a path (never as the bare name 'arm', which
    would now be a catalog name), and validate finds it again."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "arm").write_text(cc.robot_to_toml(_catalog("rr")))
    assert main(["simulate", "./arm", "--poses", "30", "-o", "m.csv"]) == 0
    assert main(["identify", "./arm", "m.csv", "-o", "cal.toml"]) == 0
    cal = cc.load_robot(tmp_path / "cal.toml")
    assert cal.calibrated_from in ("./arm", str(tmp_path / "arm"))
    assert np.allclose(nominal_of(cal).fk(np.zeros(2)), _catalog("rr").fk(np.zeros(2)))
    assert main(["validate", "cal.toml", "m.csv"]) == 0


def test_identify_records_a_catalog_nominal_as_its_name(tmp_path, monkeypatch):
    # before: with a file 'rr' in the working folder, identify rr -o sub/cal.toml recorded
    # calibrated_from = "../rr" (that file), and validate compared with it
    monkeypatch.chdir(tmp_path)
    (tmp_path / "rr").write_text(IMPOSTOR)
    (tmp_path / "sub").mkdir()
    assert main(["simulate", "rr", "--poses", "30", "-o", "m.csv"]) == 0
    assert main(["identify", "rr", "m.csv", "-o", "sub/cal.toml"]) == 0
    cal = cc.load_robot(tmp_path / "sub" / "cal.toml")
    assert cal.calibrated_from == "rr"
    assert _same(nominal_of(cal), _catalog("rr"))
