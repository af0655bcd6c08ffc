"""Shared test helpers: random robots written as TOML text, independent of casecal's writer."""

from __future__ import annotations

import contextlib
import math
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest


def random_robot_toml(
    rng: np.random.Generator,
    convention: str,
    n: int,
    *,
    length_unit: str,
    angle_unit: str,
    parallel: bool = True,
    beta: bool = False,
) -> tuple[str, dict]:
    """TOML text of a random robot, and the same numbers in SI for building an oracle.

    Some twists are set to 0 or 180 degrees (when `parallel`) so that Hayati's beta appears.
    """
    L = 1e3 if length_unit == "mm" else 1.0
    A = 180 / math.pi if angle_unit == "deg" else 1.0
    rows, joints = [], []
    for _ in range(n):
        jtype = "P" if rng.random() < 0.3 else "R"
        alpha = (
            rng.choice([0.0, math.pi])
            if parallel and rng.random() < 0.4
            else rng.uniform(-math.pi, math.pi)
        )
        j = {
            "type": jtype,
            "a": rng.uniform(-0.8, 0.8),
            "alpha": float(alpha),
            "d": rng.uniform(-0.8, 0.8),
            "theta": rng.uniform(-math.pi, math.pi),
            "beta": rng.uniform(-0.1, 0.1) if beta else None,
        }
        joints.append(j)
        text = (
            f'[[joints]]\ntype = "{jtype}"\na = {j["a"] * L!r}\nalpha = {j["alpha"] * A!r}\n'
            f"d = {j['d'] * L!r}\ntheta = {j['theta'] * A!r}\n"
        )
        if jtype == "P":
            text += f"limits = [{-0.5 * L!r}, {0.5 * L!r}]\n"
        rows.append(text)
    base = {"xyz": rng.uniform(-1, 1, 3), "rpy": rng.uniform(-math.pi, math.pi, 3)}
    tool = {"xyz": rng.uniform(-0.3, 0.3, 3), "rpy": rng.uniform(-math.pi, math.pi, 3)}

    def vec(v, s):
        return "[" + ", ".join(repr(float(x) * s) for x in v) + "]"

    head = (
        f'name = "random"\nconvention = "{convention}"\nlength_unit = "{length_unit}"\n'
        f'angle_unit = "{angle_unit}"\n'
    )
    frames = (
        f"[base]\nxyz = {vec(base['xyz'], L)}\nrpy = {vec(base['rpy'], A)}\n"
        f"[tool]\nxyz = {vec(tool['xyz'], L)}\nrpy = {vec(tool['rpy'], A)}\n"
    )
    return head + "\n".join(rows) + frames, {"joints": joints, "base": base, "tool": tool}


@pytest.fixture
def write_toml(tmp_path):
    def write(text: str, name: str = "robot.toml"):
        path = tmp_path / name
        path.write_text(text)
        return path

    return write


@pytest.fixture
def fake_report(monkeypatch):
    """`casecal report` with the studies replaced by a few files written at once: the
    folder handling is the real one. Set `.files` to choose what the next report writes;
    `.fail` to an exception the studies raise."""
    import casecal.report as rep
    import casecal.report.pdf as pdf

    class Fake:
        files: ClassVar = {"fig1.png": b"new figure", "table1.csv": b"a,b\n1,2\n"}
        fail = None

    def run_studies(names, out, quick, run, log=None):
        if Fake.fail is not None:
            raise Fake.fail
        for name, data in Fake.files.items():
            (Path(out) / name).write_bytes(data)
        return []

    monkeypatch.setattr(rep, "run_studies", run_studies)

    class Runner(contextlib.nullcontext):
        def __enter__(self):
            return self

        def check_reachable(self):
            pass

    monkeypatch.setattr(rep, "study_runner", lambda *a, **k: Runner())
    monkeypatch.setattr(pdf, "write_pdf", lambda path, *a: Path(path).write_bytes(b"new") and 0)
    return Fake
