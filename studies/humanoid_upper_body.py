"""A humanoid upper body calibrated from motion capture: a rigid model of an elastic robot.

The case of DLR's Agile Justin (issue 21): a torso of 3 actuated joints and a passive
one that keeps the chest upright (q_t4 = -(q_t2 + q_t3)), two 7-joint arms, a marker on
each hand, 500 poses. Its rigid model was published at 10.5 mm mean held-out error, 3.1
mm with elasticities: gravity bends the joints, and no rigid geometry can follow that.

This stand-in has the same structure (examples/humanoid_upper_body.urdf): a "true" robot
with 5 mm / 0.7° errors on every joint origin and marker, and joints that give under the
gravity torque of the bodies beyond them (an unmodelled, pose-dependent effect), seen by
a mocap with σ = 0.5 mm per axis. It is simulated here with its own forward kinematics
(numpy, from the URDF's text; no casecal), written as the CSV a user has, and calibrated
as a user would: the URDF's tree with the torso's coupling and humanoid-sized plausible
deviations, parameters "all", on random 250/250 splits of the 500 poses.

Prints a table: split, held-out mean (mm), in-sample mean (mm), the audit's verdict; and
the same for the robot without elasticity (the noise floor, σ·√3·0.92 ≈ 0.80 mm). Run:
    python studies/humanoid_upper_body.py [--splits 10] [--csv examples/humanoid_mocap.csv]
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

import casecal as cc
from casecal.textio import write_atomic

HERE = Path(__file__).resolve().parents[1]
URDF = HERE / "examples" / "humanoid_upper_body.urdf"
TIPS = ["right_marker", "left_marker"]
PASSIVE = "torso_4"
"""The passive torso joint: turned by -(torso_2 + torso_3), no controller joint of its own."""
SIGMA = 0.5e-3
"""The mocap's noise, m per axis."""
PUBLISHED_RIGID_MM = 10.5
"""Agile Justin's published mean held-out error of its rigid model, mm."""
MASSES = {  # kg at each link's origin: the bodies whose weight bends the joints
    "torso_link2": 6.0,
    "torso_link3": 6.0,
    "chest": 18.0,
    **{f"{s}_link{k}": m for s in ("right", "left") for k, m in ((2, 2.5), (4, 2.5), (6, 1.5))},
    **{f"{s}_palm": 1.5 for s in ("right", "left")},
}
COMPLIANCE = {"torso": 8e-5, "arm": 2.5e-4}
"""Joint compliance, rad/(N·m), of the torso's joints and the arms'."""
GRAVITY = np.array([0.0, 0.0, -9.81])


# --- the stand-in's own kinematics: URDF text to link frames, numpy only ---------------


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (f(v) for v in (r, p, y) for f in (math.cos, math.sin))
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _about(axis: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Rotations about unit `axis` by angles `q` (N,), shape (N, 3, 3) (Rodrigues)."""
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    s, c = np.sin(q)[:, None, None], np.cos(q)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def read_joints(text: str) -> list[dict]:
    """The joints of URDF `text` in the file's order: name, type, parent, child, xyz, rpy,
    axis (unit)."""
    joints = []
    for j in ET.fromstring(text).iter("joint"):
        origin = j.find("origin")
        axis = j.find("axis")
        a = np.array([float(v) for v in (axis.get("xyz") if axis is not None else "1 0 0").split()])
        joints.append(
            {
                "name": j.get("name"),
                "type": j.get("type"),
                "parent": j.find("parent").get("link"),
                "child": j.find("child").get("link"),
                "xyz": np.array([float(v) for v in origin.get("xyz").split()]),
                "rpy": np.array([float(v) for v in origin.get("rpy").split()]),
                "axis": a / np.linalg.norm(a),
            }
        )
    return joints


def link_frames(joints: list[dict], q: dict, base: np.ndarray) -> dict:
    """Every link's frame in the measurement frame, (N, 4, 4), at joint values `q` (rad by
    joint name, (N,) each); `base`: the robot's root link in the measurement frame."""
    n = len(next(iter(q.values())))
    frames = {joints[0]["parent"]: np.broadcast_to(base, (n, 4, 4)).copy()}
    for j in joints:  # a parent's joint comes before its children's in this file
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = _rpy(*j["rpy"]), j["xyz"]
        out = frames[j["parent"]] @ T
        if j["type"] != "fixed":
            turn = np.tile(np.eye(4), (n, 1, 1))
            turn[:, :3, :3] = _about(j["axis"], q[j["name"]])
            out = out @ turn
        frames[j["child"]] = out
    return frames


def _beyond(joints: list[dict]) -> dict:
    """Per movable joint, the links it moves."""
    children: dict = {}
    for j in joints:
        children.setdefault(j["parent"], []).append(j["child"])

    def below(link):
        out = [link]
        for c in children.get(link, []):
            out += below(c)
        return out

    return {j["name"]: below(j["child"]) for j in joints if j["type"] != "fixed"}


def gravity_deflection(joints: list[dict], frames: dict, base: np.ndarray) -> dict:
    """Per movable joint, its turn under the weight of the bodies it carries, rad (N,):
    compliance times the gravity torque about its axis (`MASSES`, `COMPLIANCE`)."""
    g = base[:3, :3] @ GRAVITY  # the robot stands upright in its root link's frame
    out = {}
    for j in joints:
        if j["type"] == "fixed":
            continue
        T = frames[j["child"]]  # its origin lies on the axis, its axis is in this frame
        axis, origin = T[:, :3, :3] @ j["axis"], T[:, :3, 3]
        torque = np.zeros(len(T))
        for link in _beyond(joints)[j["name"]]:
            if link in MASSES:
                arm = frames[link][:, :3, 3] - origin
                torque += np.einsum("ni,ni->n", axis, np.cross(arm, MASSES[link] * g))
        c = COMPLIANCE["torso" if j["name"].startswith("torso") else "arm"]
        out[j["name"]] = c * torque
    return out


# --- the true robot, its poses and its measurements ------------------------------------


def true_joints(seed: int) -> list[dict]:
    """The URDF's joints with every movable joint's and every marker's origin off by
    about 5 mm per axis and 0.7° per angle (Gaussian), the torso's included."""
    rng = np.random.default_rng(seed)
    joints = read_joints(URDF.read_text())
    for j in joints:
        if j["type"] != "fixed" or j["name"].endswith("marker_joint"):
            j["xyz"] = j["xyz"] + rng.normal(0, 5e-3, 3)
            j["rpy"] = j["rpy"] + rng.normal(0, math.radians(0.7), 3)
    return joints


def controller_names() -> list[str]:
    """The controller's joints, in the tree's order: every movable joint but the passive."""
    joints = read_joints(URDF.read_text())
    return [j["name"] for j in joints if j["type"] != "fixed" and j["name"] != PASSIVE]


def measure(q: np.ndarray, seed: int, elastic: bool = True, noise: float = SIGMA) -> np.ndarray:
    """The markers of the true robot (`true_joints(seed)`) at controller poses `q` (N, 17),
    rad, as the mocap sees them: (N, 2, 3) m, in a frame 2 m in front of the robot and
    turned 150° about the vertical, with `noise` (m per axis). `elastic`: the joints give
    under gravity (one fixed-point step: the deflection is a small fraction of the pose)."""
    joints = true_joints(seed)
    rng = np.random.default_rng(seed + 1)
    zero = {j["name"]: rng.normal(0, math.radians(0.3)) for j in joints if j["type"] != "fixed"}
    base = np.eye(4)
    base[:3, :3], base[:3, 3] = _rpy(0.0, 0.0, math.radians(150.0)), (2.0, 0.3, -0.8)
    by_name = dict(zip(controller_names(), q.T, strict=True))
    by_name[PASSIVE] = -(by_name["torso_2"] + by_name["torso_3"])
    model = {k: v + zero[k] for k, v in by_name.items()}
    frames = link_frames(joints, model, base)
    if elastic:
        bend = gravity_deflection(joints, frames, base)
        frames = link_frames(joints, {k: v + bend[k] for k, v in model.items()}, base)
    points = np.stack([frames[t][:, :3, 3] for t in TIPS], axis=1)
    return points + np.random.default_rng(seed + 2).normal(0, noise, points.shape)


def write_mocap_csv(path, q: np.ndarray, points: np.ndarray) -> None:
    """The file a user has: controller joints in degrees (``q1_deg`` … in the tree's order
    without the passive joint), each marker in mm, the mocap's σ."""
    columns = [f"q{i + 1}_deg" for i in range(q.shape[1])]
    columns += [f"{t}_{a}_mm" for t in TIPS for a in "xyz"]
    rows = np.column_stack([np.degrees(q), points.reshape(len(q), -1) * 1e3])
    lines = [",".join([*columns, "sigma_mm"])]
    lines += [",".join([*(f"{v:.6f}" for v in row), f"{SIGMA * 1e3:g}"]) for row in rows]
    write_atomic(path, "\n".join(lines) + "\n")  # never half a file, nor a replaced device


def user_robot():
    """The robot as a user builds it: the URDF's tree of both markers, the torso's passive
    joint coupled to the controller's, humanoid-sized plausible deviations."""
    tree = cc.load_robot(URDF, tip_link=TIPS)
    names = [j.name for j in tree.joints]
    controller = [n for n in names if n != PASSIVE]
    M = np.zeros((len(names), len(controller)))
    for i, name in enumerate(names):
        if name in controller:
            M[i, controller.index(name)] = 1.0
    M[names.index(PASSIVE), [controller.index("torso_2"), controller.index("torso_3")]] = -1.0
    return tree.with_coupling(M).with_plausible(length=0.01, angle=math.radians(2))


def poses(n: int, seed: int) -> np.ndarray:
    """`n` controller poses uniform in the URDF's limits (the torso's passive joint then
    stays within its own)."""
    return cc.poses.uniform(user_robot(), n, seed=seed)


def held_out_errors(robot, meas) -> np.ndarray:
    """Per pose and hand, the distance between the robot's markers and the measured, m."""
    return np.linalg.norm(robot.position(meas.q) - meas.positions, axis=-1)


def split_study(meas, splits: int, seed: int = 0, robot=None):
    """Random 250/250 (half/half) splits of `meas`: per split, the held-out and in-sample
    mean errors (m), the calibration, and the seconds it took."""
    robot = robot or user_robot()
    rng = np.random.default_rng(seed)
    n = len(meas.q)
    out = []
    for _ in range(splits):
        order = rng.permutation(n)
        fit, test = meas.take(np.sort(order[: n // 2])), meas.take(np.sort(order[n // 2 :]))
        start = time.perf_counter()
        cal = cc.identify(robot, fit, "all")
        seconds = time.perf_counter() - start
        out.append(
            (
                held_out_errors(cal.robot, test).mean(),
                held_out_errors(cal.robot, fit).mean(),
                cal,
                seconds,
            )
        )
    return out


def verdict(cal, full: bool = False) -> str:
    """The audit's verdict: its first failed check (its name and whether it names a
    model error; `full`: all it says), or that it passed."""
    failed = cal.audit.failures
    if not failed:
        return "audit passed"
    first = failed[0]
    if full:
        return f"{first.name}: {first.text}"
    return f"FAILED {first.name}" + (" (a model error, not noise)" if first.cause else "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--splits", type=int, default=10, help="random 250/250 splits (10)")
    parser.add_argument("--seed", type=int, default=21, help="the true robot's seed (21)")
    parser.add_argument("--csv", help="write the 500 elastic poses to this CSV file too")
    args = parser.parse_args()
    robot = user_robot()
    q = poses(500, seed=args.seed)
    floor = SIGMA * 1e3 * math.sqrt(8 / math.pi)  # mean length of a 3-D Gaussian error
    with tempfile.TemporaryDirectory() as tmp:
        for elastic in (True, False):
            path = Path(args.csv) if (args.csv and elastic) else Path(tmp) / "mocap.csv"
            write_mocap_csv(path, q, measure(q, args.seed, elastic=elastic))
            meas = cc.read_csv(path, robot)  # through the file, as a user has it
            title = "elastic (gravity bends the joints)" if elastic else "rigid (noise only)"
            print(f"\n{title}: 500 poses, sigma {SIGMA * 1e3:g} mm per axis")
            print(f"{'split':>5}  {'held-out mm':>11}  {'in-sample mm':>12}  {'s':>5}  audit")
            rows = split_study(meas, args.splits, seed=1, robot=robot)
            for k, (held, fitted, cal, seconds) in enumerate(rows, start=1):
                mm = f"{held * 1e3:>11.2f}  {fitted * 1e3:>12.2f}"
                print(f"{k:>5}  {mm}  {seconds:>5.1f}  {verdict(cal)}")
            print(f"split 1's audit: {verdict(rows[0][2], full=True)}")
            held = np.array([r[0] for r in rows]) * 1e3
            print(
                f"held-out mean over splits {held.mean():.2f} mm (worst {held.max():.2f}); "
                f"published rigid {PUBLISHED_RIGID_MM} mm; noise floor {floor:.2f} mm"
            )


if __name__ == "__main__":
    main()
