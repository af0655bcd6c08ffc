"""identify's --json, --residuals and --plot, and compensate --program, through the
installed entry point (``python -m casecal``), as a script or a shell would run them."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from test_programs import KRL_DAT, KRL_DAT_TARGETS, NUMBER  # tests/ is on the path

import casecal as cc


def casecal(*args, cwd) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "casecal", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
    )


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """A KR 16's tracker file (one gross reading) and its calibration by the command."""
    folder = tmp_path_factory.mktemp("cli_results")
    robot = cc.load_robot("kr16_2")
    q = cc.poses.uniform(robot, 150, seed=5)
    true = robot.with_deviations({"a2": 3e-4, "d4": -2e-4, "theta3": 2e-4, "a3": 1e-4})
    meas = cc.simulate(true, q, noise=2e-5, seed=6)
    y = meas.positions.copy()
    y[11] += [0.0, 2e-3, 0.0]  # 2 mm off: stands out
    cc.write_csv(folder / "m.csv", cc.Measurements(q=q, positions=y, sigma=2e-5), robot)
    run = casecal(
        "identify", "kr16_2", "m.csv", "-o", "cal.toml", "--json", "r.json", "--loss",
        "huber", "--residuals", "r.csv", "--plot", "r.png", cwd=folder,
    )  # fmt: skip
    return folder, robot, q, y, run


def test_identify_writes_json_residuals_and_plot(calibrated):
    folder, _, q, y, run = calibrated
    assert run.returncode == 0, run.stderr
    result = json.loads((folder / "r.json").read_text())
    assert result["schema"] == "casecal.calibration/1" and result["success"] is True
    assert 11 in result["outliers"]
    fitted = cc.load_robot(str(folder / "cal.toml"))
    error = np.linalg.norm(y - fitted.position(q), axis=1) * 1e3  # from the written robot
    assert result["rms_after_mm"] == pytest.approx(np.sqrt(np.mean(error**2)), rel=1e-6)
    table = pd.read_csv(folder / "r.csv")
    assert len(table) == 150 and table.loc[table.outlier, "pose"].tolist() == [11]
    assert table.error_after_mm.to_numpy() == pytest.approx(error, rel=1e-6, abs=1e-9)
    assert (folder / "r.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_failed_fit_still_says_why_in_its_json(tmp_path):
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 60, seed=1)
    true = robot.with_deviations({"alpha3": 1e-3, "d3": 5e-4})  # not what is asked for
    cc.write_csv(tmp_path / "m.csv", cc.simulate(true, q, noise=2e-5, seed=2), robot)
    run = casecal("identify", "puma560", "m.csv", "--parameters", "a2,a3", "-o", "cal.toml",
                  "--json", "r.json", cwd=tmp_path)  # fmt: skip
    assert run.returncode != 0 and not (tmp_path / "cal.toml").exists()
    result = json.loads((tmp_path / "r.json").read_text())
    assert result["success"] is False and result["audit"]["passed"] is False


def test_json_with_distances_is_refused_in_one_line(tmp_path):
    run = casecal("identify", "puma560", "p.csv", "--pairs", "d.csv", "--json", "r.json",
                  cwd=tmp_path)  # fmt: skip
    assert run.returncode != 0 and "--json" in run.stderr and run.stderr.count("\n") == 1


def test_compensate_program_changes_only_the_targets(calibrated):
    folder, _, _, _, run = calibrated
    assert run.returncode == 0, run.stderr
    (folder / "cell.dat").write_bytes(KRL_DAT.encode("cp1252").replace(b"WELD", b"W\xe4LD"))
    out = casecal("compensate", "cal.toml", "--program", "cell.dat", "-o", "new.dat",
                  "--json", "comp.json", cwd=folder)  # fmt: skip
    assert out.returncode == 0, out.stderr
    old, new = (folder / "cell.dat").read_bytes(), (folder / "new.dat").read_bytes()
    assert new.startswith(old[: old.index(b"\r\n", old.index(b"DEFDAT")) + 2])  # \xe4 kept
    header = new.split(b"\r\n")[4].decode("cp1252")
    assert header.startswith(";") and "cal.toml (sha256 " in header and "audit: passed" in header
    old_lines, new_lines = old.split(b"\r\n"), new.split(b"\r\n")
    del new_lines[4]  # the header line
    assert len(old_lines) == len(new_lines)
    for n, (a, b) in enumerate(zip(old_lines, new_lines, strict=True), start=1):
        a, b = a.decode("cp1252"), b.decode("cp1252")
        assert NUMBER.sub("#", a) == NUMBER.sub("#", b)  # only numbers changed
        assert a == b or n in KRL_DAT_TARGETS
    assert sum(a != b for a, b in zip(old_lines, new_lines, strict=True)) >= 1
    # the rest are listed with the reason (line 15's A1 190° would pass joint 1's limit)
    assert "line 15 left as it was: outside the limits of joint 1" in out.stdout
    summary = json.loads((folder / "comp.json").read_text())
    assert summary["schema"] == "casecal.compensation/1" and summary["output"] == "new.dat"
    assert 15 in [left["line"] for left in summary["left"]]
    assert summary["corrected"] == sum(a != b for a, b in zip(old_lines, new_lines, strict=True))
    # the targets are the library's (tests/test_programs.py checks where they lead)
    fitted = cc.load_robot(str(folder / "cal.toml"))
    text = old.decode("cp1252")
    from casecal.programs import calibration_header

    verdict = "passed (casecal identify wrote it after its audit)"
    library = cc.compensate_program(
        fitted, text, "krl", header=calibration_header(folder / "cal.toml", verdict)
    )
    assert new.decode("cp1252") == library.text
    refused = casecal("compensate", "cal.toml", "--program", "cell.dat", "-o", "cell.dat",
                      cwd=folder)  # fmt: skip
    assert refused.returncode != 0 and "is also the file read as program" in refused.stderr


def test_observability_and_validate_write_json(calibrated, tmp_path):
    folder, robot, _, _, run = calibrated
    assert run.returncode == 0, run.stderr
    out = casecal("observability", "scara", "--poses", "100", "--schedule", "seed", "--json",
                  tmp_path / "o.json", cwd=tmp_path)  # fmt: skip
    assert out.returncode == 0, out.stderr
    obs = json.loads((tmp_path / "o.json").read_text())
    expected = cc.observability(cc.load_robot("scara"), cc.poses.seed_schedule(
        cc.load_robot("scara"), 100))  # fmt: skip
    assert obs["schema"] == "casecal.observability/1" and obs["rank"] == expected.rank
    assert obs["unidentifiable"] == list(expected.unidentifiable)
    # held-out poses of the same true robot: the calibration's errors, recomputed here
    q = cc.poses.uniform(robot, 80, seed=21)
    true = robot.with_deviations({"a2": 3e-4, "d4": -2e-4, "theta3": 2e-4, "a3": 1e-4})
    meas = cc.simulate(true, q, noise=2e-5, seed=22)
    cc.write_csv(tmp_path / "held.csv", meas, robot)
    out = casecal("validate", folder / "cal.toml", "held.csv", "--json", "v.json",
                  cwd=tmp_path)  # fmt: skip
    assert out.returncode == 0, out.stderr
    v = json.loads((tmp_path / "v.json").read_text())
    assert v["schema"] == "casecal.validation/1" and v["n_poses"] == 80
    assert v["after"]["rms_mm"] < 0.3 * v["before"]["rms_mm"]  # the calibration helps
    assert f"{v['after']['rms_mm']:10.4f}" in out.stdout  # the printed table says the same


def test_compare_writes_json(calibrated, tmp_path):
    folder, *_ = calibrated
    out = casecal("compare", "kr16_2", folder / "m.csv", "--harmonics", "2:1", "--folds", "3",
                  "--json", "c.json", cwd=tmp_path)  # fmt: skip
    assert out.returncode == 0, out.stderr
    c = json.loads((tmp_path / "c.json").read_text())
    assert c["schema"] == "casecal.comparison/1"
    assert [m["model"] for m in c["models"]] == ["rigid", "+ harmonics 2:1"]
    assert c["best"] in ("", "rigid", "+ harmonics 2:1")
    assert all(isinstance(m["success"], bool) and m["cv_rms_mm"] > 0 for m in c["models"])
    assert f"chosen by cross-validation: {c['best']}" in out.stdout or not c["best"]


@pytest.mark.parametrize("option", ["--json", "--residuals", "--plot"])
def test_a_result_file_never_replaces_the_measurements(calibrated, tmp_path, option):
    folder, *_ = calibrated
    data = (folder / "m.csv").read_bytes()
    (tmp_path / "m.csv").write_bytes(data)
    out = casecal("identify", "kr16_2", "m.csv", option, "m.csv", cwd=tmp_path)
    assert out.returncode != 0 and "is also the file read as measurements" in out.stderr
    assert (tmp_path / "m.csv").read_bytes() == data
    both = casecal("identify", "kr16_2", "m.csv", "-o", "x.toml", option, "x.toml",
                   cwd=tmp_path)  # fmt: skip
    assert both.returncode != 0 and "both name" in both.stderr


def test_programs_keep_a_byte_order_mark_first_and_undefined_bytes_and_need_targets(calibrated):
    """A RAPID module saved with a UTF-8 BOM keeps it as its first bytes (the header comes
    after it, not before); a KRL file with a byte cp1252 leaves undefined (a GBK comment)
    keeps it; a file with no joint target is refused in one line, nothing written."""
    folder, _, _, _, run = calibrated
    assert run.returncode == 0, run.stderr
    rapid = (
        "MODULE M\r\n  CONST jointtarget j1 := [[10,20,30,40,50,60],"
        "[9E9,9E9,9E9,9E9,9E9,9E9]];\r\nENDMODULE\r\n"
    )
    (folder / "bom.mod").write_bytes(b"\xef\xbb\xbf" + rapid.encode())
    out = casecal("compensate", "cal.toml", "--program", "bom.mod", "-o", "bom_new.mod",
                  cwd=folder)  # fmt: skip
    assert out.returncode == 0, out.stderr
    new = (folder / "bom_new.mod").read_bytes()
    assert new.startswith(b"\xef\xbb\xbfMODULE M\r\n") and new.count(b"\xef\xbb\xbf") == 1
    krl = (
        "DEFDAT cell\r\n; Kommentar \x81\r\n"
        "DECL E6AXIS P1={A1 10,A2 -90,A3 90,A4 0,A5 30,A6 0}\r\nENDDAT\r\n"
    )
    (folder / "gbk.dat").write_bytes(krl.encode("latin-1"))
    out = casecal("compensate", "cal.toml", "--program", "gbk.dat", "-o", "gbk_new.dat",
                  cwd=folder)  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert b"; Kommentar \x81\r\n" in (folder / "gbk_new.dat").read_bytes()
    (folder / "none.script").write_text('def main():\n  textmsg("no targets")\nend\n')
    out = casecal("compensate", "cal.toml", "--program", "none.script", "-o", "none_new.script",
                  cwd=folder)  # fmt: skip
    assert out.returncode == 2 and out.stderr.count("\n") == 1, out.stderr
    assert "no joint targets found" in out.stderr and not (folder / "none_new.script").exists()


def test_compensated_targets_are_not_compensated_twice(calibrated):
    folder, _, _, _, run = calibrated
    assert run.returncode == 0, run.stderr
    once = casecal("compensate", "cal.toml", "m.csv", "-o", "once.csv", cwd=folder)
    assert once.returncode == 0, once.stderr
    twice = casecal("compensate", "cal.toml", "once.csv", "-o", "twice.csv", cwd=folder)
    assert twice.returncode == 2 and twice.stderr.count("\n") == 1, twice.stderr
    assert "compensated already" in twice.stderr and "applies the calibration twice" in twice.stderr
    assert not (folder / "twice.csv").exists()
