"""Random serial arms and calibration cases for the property tests (not a test module).

A case is what an engineer with a tracker meets: a nominal DH table, a real arm that
deviates from it on every DH parameter, a tracker metres away at any orientation, a
measured point that may sit at the flange, on the last axis or anywhere on the tool.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import casecal as cc
from casecal.model.frames import rpy_from_matrix

DEG = np.pi / 180


@dataclass(frozen=True)
class Case:
    nominal: cc.Robot
    true: cc.Robot
    q_fit: np.ndarray
    q_new: np.ndarray
    sigma: float
    tool_kind: str


def random_rotation(rng) -> np.ndarray:
    """Uniform on SO(3) (from a normalised Gaussian quaternion)."""
    quat = rng.normal(size=4)
    w, x, y, z = quat / np.linalg.norm(quat)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def random_arm(rng, n_joints: int, convention: str) -> cc.Robot:
    """A DH table of plausible proportions: twists of 0 or ±90° (now and then any
    angle), lengths up to 0.6 m, about one joint in five prismatic."""
    joints = []
    for _ in range(n_joints):
        kind = "P" if rng.random() < 0.2 else "R"
        alpha = (
            rng.choice([0.0, np.pi / 2, -np.pi / 2])
            if rng.random() < 0.85
            else rng.uniform(-np.pi, np.pi)
        )
        a = 0.0 if rng.random() < 0.3 else rng.uniform(0.05, 0.6)
        d = 0.0 if rng.random() < 0.3 else rng.uniform(-0.4, 0.6)
        theta = rng.choice([0.0, np.pi / 2, -np.pi / 2])
        if kind == "R":
            half = rng.uniform(90, 170) * DEG
            limits = (-half, half)
        else:
            limits = (0.0, rng.uniform(0.2, 0.6))
        joints.append(cc.Joint(kind, a=a, alpha=alpha, d=d, theta=theta, limits=limits))
    return cc.Robot(f"random{n_joints}{convention}", tuple(joints), convention=convention)


def random_case(
    seed: int,
    noisy: bool | None = None,
    n_joints: int | None = None,
    convention: str | None = None,
    tool_kind: str | None = None,
) -> Case:
    """One calibration case, reproducible from `seed` (module doc); the keyword choices
    are drawn from `seed` when not given."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 8)) if n_joints is None else n_joints
    if convention is None:
        convention = "dh" if rng.random() < 0.5 else "mdh"
    arm = random_arm(rng, n, convention)
    if tool_kind is None:
        tool_kind = str(rng.choice(["zero", "axis", "anywhere"]))
    tool = {
        "zero": (0.0, 0.0, 0.0),
        "axis": (0.0, 0.0, rng.uniform(0.05, 0.25)),
        "anywhere": tuple(rng.uniform(-0.2, 0.2, 3)),
    }[tool_kind]
    nominal = arm if tool_kind == "zero" else _with_tool(arm, tool)
    deviations = {}
    for name in nominal.parameter_names:
        if name.startswith(("base_", "tool_")):
            continue
        is_length = name[0] in "ad" and not name.startswith("alpha")
        deviations[name] = rng.uniform(-2e-3, 2e-3) if is_length else rng.uniform(-0.5, 0.5) * DEG
    R = random_rotation(rng)
    direction = rng.normal(size=3)
    offset = direction / np.linalg.norm(direction) * rng.uniform(0.0, 5.0)
    deviations.update(zip(("base_x", "base_y", "base_z"), offset, strict=True))
    deviations.update(zip(("base_rx", "base_ry", "base_rz"), rpy_from_matrix(R), strict=True))
    true = nominal.with_deviations(deviations)
    noisy = bool(rng.random() < 0.5) if noisy is None else noisy
    return Case(
        nominal=nominal,
        true=true,
        q_fit=cc.poses.uniform(nominal, 100, seed=seed + 1),
        q_new=cc.poses.uniform(nominal, 300, seed=seed + 2),
        sigma=0.01e-3 if noisy else 0.0,
        tool_kind=tool_kind,
    )


def _with_tool(robot: cc.Robot, xyz) -> cc.Robot:
    import dataclasses

    return dataclasses.replace(robot, tool=cc.Frame(tuple(float(v) for v in xyz)), auto_beta=False)


def outcome(case: Case, method: str | None = None):
    """Fit `case` with ``parameters="all"`` and judge the result.

    Returns
    -------
    verdict : str
        ``"reached"`` (success and the held-out error at the noise floor), ``"refused"``
        (success=False, an honest failure), or ``"SILENT"`` (success with a wrong robot).
    detail : str
    cal : Calibration or None
    """
    meas = cc.simulate(case.true, case.q_fit, noise=case.sigma, seed=7)
    kwargs = {} if method is None else {"method": method}
    try:
        cal = cc.identify(case.nominal, meas, "all", **kwargs)
    except cc.CalibrationError as exc:
        return "refused", f"CalibrationError: {exc}", None
    truth = case.true.position(case.q_new)
    model = cal.robot.position(case.q_new)
    if case.sigma == 0:
        rms = float(np.sqrt(np.mean(np.sum((model - truth) ** 2, axis=1))))
        ok, detail = rms <= 1e-9, f"held-out RMS {rms:.3g} m (limit 1e-9)"
    else:
        held_out = cc.simulate(case.true, case.q_new, noise=case.sigma, seed=8).positions
        rms = float(np.sqrt(np.mean(np.sum((model - held_out) ** 2, axis=1))))
        predicted = predicted_holdout_rms(cal, case.q_new, case.sigma)
        ok = rms <= 1.5 * predicted
        detail = f"held-out RMS {rms * 1e3:.4g} mm, predicted {predicted * 1e3:.4g} mm"
    if not cal.success:
        return "refused", f"{cal.message} | {detail}", cal
    return ("reached" if ok else "SILENT"), detail, cal


def predicted_holdout_rms(cal, q, sigma: float) -> float:
    """RMS error on new noisy measurements that the covariance predicts, m:
    ``sqrt(3 σ² + mean trace(J C Jᵀ))``."""
    J, _ = cal.robot.position_jacobian(q, list(cal.estimated))
    var = np.einsum("nik,kl,nil->n", J, cal.covariance, J)
    return float(np.sqrt(3 * sigma**2 + np.mean(var)))


def _strategy():
    from hypothesis import strategies as st

    return st.builds(
        random_case,
        seed=st.integers(0, 2**31),
        noisy=st.booleans(),
        n_joints=st.integers(3, 7),
        convention=st.sampled_from(["dh", "mdh"]),
        tool_kind=st.sampled_from(["zero", "axis", "anywhere"]),
    )


CASES = _strategy()
"""The property tests' hypothesis strategy over `random_case`."""
