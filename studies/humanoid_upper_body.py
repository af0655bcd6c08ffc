"""A humanoid upper body calibrated from motion capture: rigid, then elastic models.

The case of DLR's Agile Justin (issues 21, 22): a torso of 3 actuated joints and a passive
one that keeps the chest upright (q_t4 = -(q_t2 + q_t3)), two 7-joint arms, a marker on
each hand, 500 poses. Published held-out mean errors: 10.5 mm for the rigid model, 5.6 mm
with joint elasticity, 3.1 mm with lateral elasticity as well (Tenhumberg & Bäuml,
Humanoids 2021): gravity bends the joints, and no rigid geometry can follow that.

This stand-in has the same structure (examples/humanoid_upper_body.urdf, with the CAD's
masses): a "true" robot with 5 mm / 0.7° errors on every joint origin and marker, joints
that turn about their axes and bend across them under the gravity of everything they
carry, seen by a mocap with σ = 0.5 mm per axis. It is simulated here with its own
forward kinematics and elasticity (numpy, from the URDF's text; no casecal), written as
the CSV a user has, and calibrated as a user would: the URDF's tree with the torso's
coupling and humanoid-sized plausible deviations, parameters "all", on random 250/250
splits of the 500 poses, as a rigid tree, with joint compliance, and with joint and
lateral compliance (`Robot.with_compliance(lateral=True)`).

Prints per model a table: split, held-out mean (mm), in-sample mean (mm), seconds, the
audit's verdict; and the rigid tree on a robot without elasticity (the noise floor,
σ·√3·0.92 ≈ 0.80 mm). Run:
    python studies/humanoid_upper_body.py [--splits 10] [--csv examples/humanoid_mocap.csv]
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

import casecal as cc
from casecal.report.studies_elastic import BENDING, COMPLIANCE, humanoid
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


def read_masses(text: str) -> dict:
    """Each link's mass (kg) and centre of mass (m, link frame) from URDF `text`'s
    ``<inertial>`` tags: the CAD's masses."""
    out = {}
    for link in ET.fromstring(text).iter("link"):
        inertial = link.find("inertial")
        if inertial is not None:
            origin = inertial.find("origin")
            com = [0.0] * 3 if origin is None else [float(v) for v in origin.get("xyz").split()]
            out[link.get("name")] = (float(inertial.find("mass").get("value")), np.array(com))
    return out


def across(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit axes across a joint's `axis`, in its child frame: the frame's axis least
    aligned with it (x on ties), made perpendicular, then `axis` × that one."""
    e = np.eye(3)[int(np.argmin(np.abs(axis)))]
    u = e - (e @ axis) * axis
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)


def link_frames(joints: list[dict], q: dict, base: np.ndarray, bend: dict | None = None) -> dict:
    """Every link's frame in the measurement frame, (N, 4, 4), at joint values `q` (rad by
    joint name, (N,) each); `base`: the robot's root link in the measurement frame.
    `bend`: per joint name, (N, 2) turns (rad) of its child frame about `across` its axis,
    after the joint's own turn (the joint's bearings and links giving across the axis)."""
    n = len(next(iter(q.values())))
    frames = {joints[0]["parent"]: np.broadcast_to(base, (n, 4, 4)).copy()}
    for j in joints:  # a parent's joint comes before its children's in this file
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = _rpy(*j["rpy"]), j["xyz"]
        out = frames[j["parent"]] @ T
        if j["type"] != "fixed":
            turn = np.tile(np.eye(4), (n, 1, 1))
            turn[:, :3, :3] = _about(j["axis"], q[j["name"]])
            if bend is not None and j["name"] in bend:
                u, v = across(j["axis"])
                angles = bend[j["name"]]
                turn[:, :3, :3] = (
                    turn[:, :3, :3] @ _about(u, angles[:, 0]) @ _about(v, angles[:, 1])
                )
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


def gravity_deflection(joints: list[dict], frames: dict, base: np.ndarray, masses: dict):
    """Per movable joint, its turn about its axis (rad, (N,)) and across it (rad, (N, 2)),
    under the weight of the bodies it carries (`masses`: link → (kg, centre of mass m));
    compliances `COMPLIANCE` and `BENDING`. The moments are the rigid robot's (one step:
    the deflection is a small fraction of the pose)."""
    g = base[:3, :3] @ GRAVITY  # the robot stands upright in its root link's frame
    torsion, lateral = {}, {}
    for j in joints:
        if j["type"] == "fixed":
            continue
        T = frames[j["child"]]  # its origin lies on the axis, its axis is in this frame
        origin = T[:, :3, 3]
        moment = np.zeros((len(T), 3))
        for link in _beyond(joints)[j["name"]]:
            if link in masses:
                mass, com = masses[link]
                centre = frames[link][:, :3, :3] @ com + frames[link][:, :3, 3]
                moment += np.cross(centre - origin, mass * g)
        local = np.einsum("nji,nj->ni", T[:, :3, :3], moment)  # in the child frame
        u, v = across(j["axis"])
        part = "torso" if j["name"].startswith("torso") else "arm"
        torsion[j["name"]] = COMPLIANCE[part] * (local @ j["axis"])
        lateral[j["name"]] = np.column_stack([local @ u, local @ v]) * BENDING[part]
    return torsion, lateral


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


def measure(
    q: np.ndarray, seed: int, elastic: bool = True, noise: float = SIGMA, bending: bool = True
) -> np.ndarray:
    """The markers of the true robot (`true_joints(seed)`) at controller poses `q` (N, 17),
    rad, as the mocap sees them: (N, 2, 3) m, in a frame 2 m in front of the robot and
    turned 150° about the vertical, with `noise` (m per axis). `elastic`: the joints turn
    under gravity (`gravity_deflection`, the URDF's masses) and, with `bending`, give
    across their axes too."""
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
        torsion, lateral = gravity_deflection(joints, frames, base, read_masses(URDF.read_text()))
        turned = {k: v + torsion[k] for k, v in model.items()}
        frames = link_frames(joints, turned, base, lateral if bending else None)
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
    joint coupled to the controller's, humanoid-sized plausible deviations
    (`casecal.report.studies_elastic.humanoid`)."""
    return humanoid()


MODELS = {
    "rigid": lambda: user_robot(),
    "joint": lambda: user_robot().with_compliance(),
    "joint + lateral": lambda: user_robot().with_compliance(lateral=True),
}
"""The models calibrated: the rigid tree, joint compliance, joint and lateral compliance."""


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
    # a kill (SIGTERM) unwinds like Ctrl-C: the temporary folder below is removed
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    q = poses(500, seed=args.seed)
    floor = SIGMA * 1e3 * math.sqrt(8 / math.pi)  # mean length of a 3-D Gaussian error
    published = dict(zip(MODELS, (PUBLISHED_RIGID_MM, 5.6, 3.1), strict=True))
    runs = [(True, name) for name in MODELS] + [(False, "rigid")]
    with tempfile.TemporaryDirectory() as tmp:
        for elastic, model in runs:
            robot = MODELS[model]()
            path = Path(args.csv) if (args.csv and elastic) else Path(tmp) / "mocap.csv"
            write_mocap_csv(path, q, measure(q, args.seed, elastic=elastic))
            meas = cc.read_csv(path, robot)  # through the file, as a user has it
            title = "elastic robot" if elastic else "rigid robot (noise only)"
            print(f"\n{title}, {model} model: 500 poses, sigma {SIGMA * 1e3:g} mm per axis")
            print(f"{'split':>5}  {'held-out mm':>11}  {'in-sample mm':>12}  {'s':>5}  audit")
            rows = split_study(meas, args.splits, seed=1, robot=robot)
            for k, (held, fitted, cal, seconds) in enumerate(rows, start=1):
                mm = f"{held * 1e3:>11.2f}  {fitted * 1e3:>12.2f}"
                print(f"{k:>5}  {mm}  {seconds:>5.1f}  {verdict(cal)}", flush=True)
            print(f"split 1's audit: {verdict(rows[0][2], full=True)}")
            held = np.array([r[0] for r in rows]) * 1e3
            shown = f"published {published[model]} mm; " if elastic else ""
            print(
                f"held-out mean over splits {held.mean():.2f} mm (worst {held.max():.2f}); "
                f"{shown}noise floor {floor:.2f} mm"
            )


if __name__ == "__main__":
    main()
