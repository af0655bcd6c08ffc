"""A calibration as plain data and as a picture: the JSON-ready dict, the per-point
residual table, the residual plot."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import casecal as cc


@pytest.fixture(scope="module")
def fitted():
    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 120, seed=3)
    true = robot.with_deviations({"a2": 2e-4, "d3": -1e-4, "alpha3": 3e-4})
    meas = cc.simulate(true, q, noise=2e-5, seed=4)
    y = meas.positions.copy()
    y[7] += [3e-3, 0.0, 0.0]  # one gross reading: 3 mm
    meas = cc.Measurements(q=q, positions=y, sigma=2e-5)
    return robot, q, y, cc.identify(robot, meas)


def test_the_dict_is_json_with_units_in_its_keys(fitted):
    _, q, y, cal = fitted
    d = cal.to_dict()
    back = json.loads(json.dumps(d, allow_nan=False))  # NaN would not be JSON
    assert back["schema"] == "casecal.calibration/1" and back["n_poses"] == 120
    assert back["success"] == cal.success and back["audit"]["passed"] == cal.audit.passed
    # the errors after calibration, from the calibrated robot's own forward kinematics
    error = np.linalg.norm(y - cal.robot.position(q), axis=1) * 1e3
    assert back["rms_after_mm"] == pytest.approx(np.sqrt(np.mean(error**2)), rel=1e-9)
    assert back["max_error_after_mm"] == pytest.approx(error.max(), rel=1e-9)
    for entry in back["parameters"]:
        name = entry["parameter"]
        factor = {"mm": 1e3, "deg": 180 / math.pi}[entry["unit"]]
        assert entry["deviation"] == pytest.approx(cal.deviations[name] * factor, abs=1e-12)
        assert back["deviations_si"][name] == pytest.approx(cal.deviations[name], abs=1e-15)
        if name in cal.estimated:
            assert entry["std_error"] > 0
        else:  # held: no standard error, None rather than NaN
            assert entry["std_error"] is None and name in back["held"]


def test_the_residual_table_flags_the_gross_reading(fitted):
    robot, q, y, cal = fitted
    assert 7 in cal.outliers
    table = cal.residual_table()
    assert len(table) == 120 and set(table[table.outlier].pose) == set(cal.outliers)
    before = np.linalg.norm(y - robot.position(q), axis=1) * 1e3
    assert table.error_before_mm.to_numpy() == pytest.approx(before, rel=1e-9)
    assert table.loc[7, "dx_after_mm"] > 2.5  # the 3 mm stays in the residual


def test_the_residual_plot_marks_what_stands_out(fitted, tmp_path):
    from matplotlib.image import imread

    from casecal.report.residual_plot import plot_residuals, residual_figure

    robot, q, _, cal = fitted
    fig = residual_figure(cal, q)
    marked = [line for ax in fig.axes for line in ax.lines if line.get_gid() == "outliers"]
    assert len(marked) == 1 and list(marked[0].get_xdata()) == list(cal.outliers)
    assert len(fig.axes) == 2 + robot.dof  # by pose, distribution, one per joint
    png = plot_residuals(cal, q, tmp_path / "residuals.png")
    assert imread(png).shape[0] > 300
    with pytest.raises(ValueError, match="poses"):
        residual_figure(cal, q[:-1])
    # a file's per-pose inputs (payload_kg) after the joints: one panel per joint still
    with_inputs = np.hstack([q, np.full((len(q), 1), 5.0)])
    assert len(residual_figure(cal, with_inputs).axes) == 2 + robot.dof


def test_the_residual_table_refuses_distances_in_one_line():
    from casecal.identification.distances import identify_distances, simulate_distances

    robot = cc.load_robot("puma560")
    q = cc.poses.uniform(robot, 60, seed=0)
    pairs = np.array([(i, (7 * i + 3) % 60) for i in range(60) if i != (7 * i + 3) % 60])
    meas = simulate_distances(robot.with_deviations({"a2": 2e-4}), q, pairs, 1e-5, seed=1)
    cal = identify_distances(robot, meas, ["a2", "a3", "d3"])
    with pytest.raises(cc.CalibrationError, match="measured distances"):
        cal.residual_table()
