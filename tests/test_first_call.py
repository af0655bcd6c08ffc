"""What a first `identify` in a new process loads: no pandas for data already in memory
(its import took 0.5 s of a 0.8 s first call; tables and files load it when asked)."""

from __future__ import annotations

import subprocess
import sys

PROBE = """
import sys
import casecal as cc
robot = cc.load_robot("puma560")
q = cc.poses.uniform(robot, 60, seed=0)
cal = cc.identify(robot, cc.simulate(robot.with_deviations({"a2": 1e-4}), q, noise=2e-5, seed=1))
assert cal.success, cal.message
print("pandas" in sys.modules)
cal.table  # the table is a DataFrame: pandas now
print("pandas" in sys.modules)
"""


def test_identify_on_data_in_memory_does_not_import_pandas():
    out = subprocess.run(
        [sys.executable, "-c", PROBE], capture_output=True, text=True, check=True, timeout=300
    ).stdout.split()
    assert out == ["False", "True"]
