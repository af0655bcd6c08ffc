"""Write two simulated laser-tracker sessions of one PUMA 560 into examples/.

tracker_session.csv: two reflectors on the tool, the tracker 2.9 m away and turned by
130°, σ = 0.02 mm, 40 uniform poses; the robot's DH parameters deviate by 0.5-1 mm and
0.1-0.5°. tracker_next_session.csv: the same robot a day later, 30 other poses, the tracker
set up elsewhere (1.5 m away, turned -40°). Then, as in the README:

    casecal identify puma560 examples/tracker_session.csv --parameters all \\
        --holdout 0.25 -o out/calibrated.toml
    casecal validate out/calibrated.toml examples/tracker_next_session.csv
"""

from pathlib import Path

import numpy as np

import casecal as cc
from casecal.data.files import write_csv
from casecal.model.parameters import select

robot = cc.load_robot("puma560")
rng = np.random.default_rng(2026)
truth = {}
for name in select(robot.parameter_names, ["theta*", "d*", "a*", "alpha*"]):
    size = rng.uniform(0.5e-3, 1e-3) if name[0] in "ad" else np.deg2rad(rng.uniform(0.1, 0.5))
    truth[name] = rng.choice([-1, 1]) * size
truth.update(base_x=2.1, base_y=-1.9, base_z=0.4, base_rz=np.deg2rad(130.0))
true = robot.with_deviations(truth).with_points([[0.04, 0.0, 0.13], [-0.03, 0.02, 0.11]])
q = cc.poses.uniform(robot, 40, seed=7)
meas = cc.simulate(true, q, noise=0.02e-3, seed=8)
write_csv(Path(__file__).with_name("tracker_session.csv"), meas, true)

# a day later: the tracker stands elsewhere; the robot (and its reflectors) are the same
moved = true.with_parameters(
    {"base_x": -1.2, "base_y": 0.9, "base_z": 0.1, "base_rz": np.deg2rad(-40.0)}
)
q_next = cc.poses.uniform(robot, 30, seed=17)
next_session = cc.simulate(moved, q_next, noise=0.02e-3, seed=18)
write_csv(Path(__file__).with_name("tracker_next_session.csv"), next_session, moved)
