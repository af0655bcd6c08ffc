"""The paper's own studies: Table 1 re-made, the planar arms, the SCARA's blind spots."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from ..data.measurements import simulate
from ..design import poses
from ..identification.analysis import RANK_TOLERANCE, observability
from ..identification.fit import identify
from ..model.catalog import load_robot
from .common import COLORS, DEG, METHOD_LABEL, StudyResult, save, table

# Table 1 of Simpson & Hayes: synthetic deviation, identified, error % (deg or mm)
PAPER_TABLE1 = {
    "theta1": (0.010000, 0.010001, 0.0980),
    "theta2": (-0.005000, -0.005007, 0.1454),
    "theta3": (0.007500, 0.007514, 0.1813),
    "theta4": (-0.008500, -0.008510, 0.1167),
    "a1": (0.1500, 0.1500, -0.0279),
    "a2": (-0.2000, -0.2000, 0.0194),
    "a3": (0.1250, 0.1250, 0.0095),
    "d1": (-0.1750, -0.1749, -0.0477),
    "d5": (0.2500, 0.2501, 0.0208),
}


def table1_truth() -> dict[str, float]:
    """The nine synthetic deviations of Table 1, SI."""
    return {n: v[0] * (DEG if n.startswith("theta") else 1e-3) for n, v in PAPER_TABLE1.items()}


def label(name: str) -> str:
    """Δθ1, Δa2 … for axis labels."""
    return "Δ" + name.replace("theta", "θ").replace("alpha", "α").replace("beta", "β")


def _why(spot) -> str:
    """Why a blind group is blind, without repeating its members or combinations."""
    if len(spot.members) == 1:
        return "its column is zero: it moves nothing measured at these poses"
    if spot.visible:
        return "their columns are parallel: only one combination moves what is measured"
    return "their columns are dependent: some combinations move nothing measured"


def table1(out: Path, quick: bool = False, run=None) -> StudyResult:
    """Scorbot, the paper's schedule, the nine deviations, no noise: one-shot and iterated."""
    res = StudyResult("table1", "The paper's Table 1, re-made")
    robot = load_robot("scorbot")
    truth = table1_truth()
    true = robot.with_deviations(truth)
    cals = {}
    for n in (100, 25):
        meas = simulate(true, poses.seed_schedule(robot, n))
        for method in ("svd", "gauss-newton"):
            cals[n, method] = identify(robot, meas, list(truth), method, truth=truth)
    rows = []
    for name, (syn, ident, err) in PAPER_TABLE1.items():
        unit, f = ("deg", 1 / DEG) if name.startswith("theta") else ("mm", 1e3)
        row = {
            "deviation": label(name),
            "unit": unit,
            "synthetic": syn,
            "paper identified": ident,
            # the paper divides by the signed synthetic value; casecal by its magnitude
            "paper error %": err * np.sign(syn),
            "paper error % (as printed)": err,
        }
        for (n, method), cal in cals.items():
            kind = "one-shot" if method == "svd" else "iterated"
            row[f"{kind} {n} poses"] = cal.deviations[name] * f
            row[f"{kind} {n} error %"] = 100 * cal.errors()[name]
        rows.append(row)
    df = pd.DataFrame(rows)
    worst = {k: max(abs(v) for v in c.errors().values()) * 100 for k, c in cals.items()}
    shown = df[
        [
            "deviation",
            "unit",
            "synthetic",
            "paper identified",
            "paper error %",
            "one-shot 100 poses",
            "one-shot 100 error %",
            "iterated 100 poses",
            "iterated 100 error %",
            "one-shot 25 error %",
            "iterated 25 error %",
        ]
    ]
    res.tables.append(
        table(
            df,
            out,
            "table1",
            "The paper's Table 1 re-made: Scorbot, its schedule, no noise",
            f"The nine synthetic deviations of the paper's Table 1 on the Scorbot-ER, identified from "
            f"its pose schedule (all joints turned together in 1° steps). One SVD step at nominal "
            f"(the paper's method) leaves a worst error of {worst[100, 'svd']:.3f} % at 100 poses "
            f"(paper: 0.1813 %) and {worst[25, 'svd']:.2f} % at 25 poses (paper: about 2 %); "
            f"the iterated Gauss-Newton brings every deviation to {worst[100, 'gauss-newton']:.1e} % "
            f"(100 poses) and {worst[25, 'gauss-newton']:.1e} % (25 poses). The one-shot error is the "
            "second-order remainder of the linearisation, not noise: iterating removes it. "
            "The 25-pose identified values are in table1.csv. Errors are 100 (identified − "
            "synthetic) / |synthetic|; the paper divides by the signed synthetic value, so its "
            "column is shown here with the sign flipped on the negative rows (Δθ2, Δθ4, Δa2, Δd1; "
            "as printed in table1.csv). The paper's Δθ1 row is inconsistent: 0.010001° against "
            "0.010000° is an error of 0.01 %, not the 0.0980 % printed.",
            shown=shown,
        )
    )

    fig, axes = plt.subplots(
        1, 3, figsize=(10, 3.4), width_ratios=[0.55, 0.75, 1.3], gridspec_kw={"wspace": 0.45}
    )
    names = list(PAPER_TABLE1)
    x = np.arange(len(names))
    for ax, kind, unit, f in ((axes[0], "theta", "deg", 1 / DEG), (axes[1], "ad", "mm", 1e3)):
        group = [n for n in names if n.startswith("theta") == (kind == "theta")]
        xg = np.arange(len(group))
        ax.bar(xg - 0.2, [PAPER_TABLE1[n][0] for n in group], 0.4, label="synthetic", color="0.6")
        ax.bar(
            xg + 0.2,
            [cals[100, "svd"].deviations[n] * f for n in group],
            0.4,
            label="identified, one-shot, 100 poses",
            color=COLORS["svd"],
        )
        ax.set_xticks(xg, [label(n) for n in group], rotation=45)
        ax.set_ylabel(f"deviation ({unit})")
        ax.axhline(0, color="k", lw=0.5)
    axes[0].set_title("angles", loc="left")
    axes[1].set_title("lengths", loc="left")
    axes[0].legend(loc="upper left", bbox_to_anchor=(0.0, -0.3), ncols=2, fontsize=7)
    ax = axes[2]
    series = [
        ("paper, 100 poses", np.abs([PAPER_TABLE1[n][2] for n in names]), "0.4"),
        (
            "one-shot, 100 poses",
            [abs(cals[100, "svd"].errors()[n]) * 100 for n in names],
            COLORS["svd"],
        ),
        ("one-shot, 25 poses", [abs(cals[25, "svd"].errors()[n]) * 100 for n in names], "#ff9896"),
        (
            "iterated, 100 poses",
            [abs(cals[100, "gauss-newton"].errors()[n]) * 100 for n in names],
            COLORS["gauss-newton"],
        ),
        (
            "iterated, 25 poses",
            [abs(cals[25, "gauss-newton"].errors()[n]) * 100 for n in names],
            "#9ecae1",
        ),
    ]
    w = 0.8 / len(series)
    for i, (name_, values, color) in enumerate(series):
        offset = (i - (len(series) - 1) / 2) * w
        ax.bar(x + offset, np.maximum(values, 1e-12), w, label=name_, color=color)
    ax.set_yscale("log")
    ax.set_xticks(x, [label(n) for n in names], rotation=45)
    ax.set_ylabel("|error| (%)")
    ax.set_title("identification error per parameter")
    ax.set_ylim(1e-13, 10)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.3), ncols=3, fontsize=7)
    res.figures.append(
        save(
            fig,
            out,
            "table1_bars",
            "Table 1: synthetic against identified, per parameter",
            "Left and middle: the nine synthetic deviations (angles in degrees, lengths in mm) "
            "and those one SVD step identifies; they are indistinguishable at this scale. Right: the error of each, on a log scale, for the "
            "paper, our one-shot step at 100 and 25 poses, and Gauss-Newton at 100 and 25 poses (as "
            "in Table 1). Our one-shot errors are of the paper's order (tenths of a percent); the "
            "iterated errors sit at the rounding floor, five to ten orders lower. The one-shot method is good enough when deviations are "
            "small; iterating costs two more steps and removes its bias entirely.",
        )
    )
    return res


def planar_arms(out: Path, quick: bool = False, run=None) -> StudyResult:
    """R, RR, RRR: error after one SVD step against the size of the deviations, 10 poses."""
    res = StudyResult("planar_arms", "Planar arms R, RR, RRR")
    ratios = np.logspace(-6, -2, 5 if quick else 9)
    rows = []
    for name in ("r", "rr", "rrr"):
        robot = load_robot(name)
        q = poses.seed_schedule(robot, 10)
        obs = observability(robot, q, ["theta*", "a*"])
        for ratio in ratios:
            truth = {}
            for i in range(1, robot.dof + 1):
                sign = (-1) ** i
                truth[f"theta{i}"] = sign * ratio  # rad: a lever of length 1 moves by ratio
                truth[f"a{i}"] = -sign * 1.2 * ratio * robot.joints[i - 1].a
            truth = {k: v for k, v in truth.items() if k in obs.identifiable}
            meas = simulate(robot.with_deviations(truth), q)
            for method in ("svd", "gauss-newton"):
                cal = identify(robot, meas, ["theta*", "a*"], method, truth=truth)
                errs = cal.errors()
                rows.append(
                    {
                        "robot": name,
                        "deviation / link length": ratio,
                        "method": method,
                        "worst error %": 100 * max(abs(e) for e in errs.values()),
                        "identified": len(errs),
                        "unidentifiable": ", ".join(obs.unidentifiable),
                    }
                )
    df = pd.DataFrame(rows)
    fig, ax = plt.subplots(figsize=(6.5, 3.6))
    markers = {"r": "o", "rr": "s", "rrr": "^"}
    for (name, method), g in df.groupby(["robot", "method"]):
        ax.loglog(
            g["deviation / link length"],
            np.maximum(g["worst error %"], 1e-12),
            marker=markers[name],
            color=COLORS[method],
            label=f"{name.upper()}, {METHOD_LABEL[method]}",
        )
    ax.axhline(0.01, color="k", ls="--", lw=0.8)
    ax.text(ratios[0], 0.013, "paper's claim: < 0.01 %", fontsize=8)
    ax.axvline(1e-4, color="k", ls=":", lw=0.8)
    ax.set_xlabel("deviation / link length (θ in rad, a relative to its link)")
    ax.set_ylabel("worst identification error (%)")
    ax.set_title("10 poses of the paper's schedule, no noise")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    one = df[df.method == "svd"]
    slope = np.polyfit(np.log(one["deviation / link length"]), np.log(one["worst error %"]), 1)[0]
    at = one[np.isclose(one["deviation / link length"], 1e-4)]["worst error %"].max()
    blind = {
        n: df[df.robot == n]["unidentifiable"].iloc[0] or "nothing" for n in ("r", "rr", "rrr")
    }
    res.figures.append(
        save(
            fig,
            out,
            "planar_arms",
            "Planar arms: the one-shot error is second order",
            f"Worst error of θ and a after one SVD step (red; the three arms' lines coincide) and "
            f"after Gauss-Newton (blue), from 10 poses of the paper's schedule, against the size of "
            f"the deviations. The one-shot error "
            f"grows in proportion to the deviation (fitted slope {slope:.2f}): the linearisation "
            f"reads Δθ through the nominal lever a instead of a + Δa. At deviations of 1e-4 of the "
            f"link length it is {at:.3f} %, the paper's 0.01 % claim and its stated condition. "
            f"Iterating removes the bias at every size (its relative error is the rounding floor "
            f"divided by the deviation, so it rises as they shrink). Blind at these poses: R {blind['r']}; "
            f"RR {blind['rr']}; RRR {blind['rrr']}.",
        )
    )
    res.tables.append(
        table(df, out, "planar_arms", "Planar arms", "Data of the planar-arm figure.")
    )
    return res


def scara_observability(out: Path, quick: bool = False, run=None) -> StudyResult:
    """What the SCARA cannot see from positions, and why, for both pose schedules."""
    res = StudyResult("scara", "SCARA observability")
    robot = load_robot("scara")
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4), sharey=True)
    rows = []
    for ax, schedule in zip(axes, ("seed", "uniform"), strict=True):
        q = (
            poses.seed_schedule(robot, 100)
            if schedule == "seed"
            else poses.uniform(robot, 100, seed=0)
        )
        obs = observability(robot, q)
        s = np.maximum(obs.singular_values, 1e-17)
        ax.bar(
            np.arange(1, s.size + 1),
            s,
            color=[COLORS["uniform"] if i < obs.rank else "0.7" for i in range(s.size)],
        )
        ax.axhline(RANK_TOLERANCE * s[0], color="k", ls="--", lw=0.8)
        if schedule == "seed":  # over the grey bars' end, which stay decades below it
            ax.text(
                s.size + 0.4,
                RANK_TOLERANCE * s[0] * 3,
                "rank threshold",
                fontsize=7,
                ha="right",
                va="bottom",
            )
        ax.set_yscale("log")
        ax.set_xlabel("singular value index")
        ax.set_title(
            f"{'paper' if schedule == 'seed' else 'uniform'} poses (100): rank "
            f"{obs.rank} of {len(obs.parameters)}"
        )
        if schedule == "uniform":
            uniform_texts = [spot.text for spot in obs.blind_spots]
        for spot in obs.blind_spots:
            rows.append(
                {
                    "schedule": schedule,
                    "parameters": ", ".join(spot.members),
                    "the data see": spot.visible or "nothing",
                    "blind": "; ".join(spot.blind),
                    "why": _why(spot),
                }
            )
    axes[0].set_ylabel("singular value of the scaled Jacobian")
    df = pd.DataFrame(rows)
    words = "; ".join(uniform_texts)
    res.figures.append(
        save(
            fig,
            out,
            "scara_singular_values",
            "SCARA: what positions cannot show",
            f"Singular values of the column-scaled identification Jacobian of the Adept Cobra 600 "
            f"(θ, a, d of its four joints), for the paper's schedule and for uniform poses; grey bars "
            f"fall below the rank threshold and are blind directions. With uniform poses: {words}. "
            f"As the paper found, the vertical offsets d cannot be told apart (only their signed sum "
            f"moves the tool up or down) and θ4 cannot be seen because the tool point lies on the "
            f"last axis; more poses do not help, only another measurement (orientation, or a tool "
            f"point off the axis) does.",
        )
    )
    res.tables.append(
        table(
            df,
            out,
            "scara_blind_spots",
            "SCARA: the blind groups and what the data see of each",
            "Per pose schedule, each group of parameters the positions cannot separate: the "
            "combination the data see (estimated in place of the members), the combinations "
            "that move no measured point, and why (mm and rad; 100 poses).",
        )
    )
    return res
