"""Issue 19, case 10: nothing the summary calls poorly determined is written."""

from __future__ import annotations

import numpy as np

import casecal as cc
from casecal.cli import main
from casecal.model.catalog import load_deviations

DEG = np.pi / 180


def test_the_readme_scorbot_example_writes_no_poorly_determined_value(tmp_path, capsys):
    """The README's example: 100 poses of the paper's schedule, θ, a, d. On main the fit
    passed with θ4 ± 156°, a4 ± 396 mm, θ5 ± 18.6° and the file held θ5 = 0.753°."""
    meas, out = tmp_path / "meas.csv", tmp_path / "scorbot.toml"
    table = "examples/scorbot_table1.toml"
    assert main(["simulate", "scorbot", "--poses", "100", "--deviations", table,
                 "--noise", "0.01mm", "-o", str(meas)]) == 0  # fmt: skip
    code = main(["identify", "scorbot", str(meas), "--parameters", "theta*,a*,d*", "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0
    assert "theta5 ± 18.6 deg" in text and "not written" in text
    nominal, written = cc.load_robot("scorbot"), cc.load_robot(out)
    for name in ("theta4", "a4", "theta5"):
        assert written.parameters[name] == nominal.parameters[name], name
    # the truth the file was simulated from, against the written robot across the
    # workspace: better than the nominal robot, as the summary's prediction says
    true = nominal.with_deviations(load_deviations(table, nominal))
    q = cc.poses.uniform(nominal, 300, seed=1)

    def rms(robot):
        return np.sqrt(np.mean(np.sum((robot.position(q) - true.position(q)) ** 2, axis=1)))

    assert rms(written) < 0.5 * rms(nominal), (rms(written), rms(nominal))
