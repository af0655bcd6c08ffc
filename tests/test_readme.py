"""The README's examples run as pasted, in order, in a fresh folder (issue 10).

Every ```python block runs in one session (as a user pastes them into one interpreter),
every ```bash block in a shell, every ```toml block is loaded as a robot file; the blocks
that install casecal or run the test suite are CI's, not the examples'. The fresh folder
holds what a clone holds that the examples read (examples/), nothing else.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

import casecal as cc

ROOT = Path(__file__).parents[1]
BLOCK = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)


def blocks():
    text = (ROOT / "README.md").read_text()
    return [(lang, body) for lang, body in BLOCK.findall(text)]


def is_ci(body: str) -> bool:
    return body.lstrip().startswith("pip install")


def test_the_readme_has_runnable_examples():
    kinds = [lang for lang, body in blocks() if not is_ci(body)]
    assert kinds.count("python") >= 2 and kinds.count("bash") >= 3 and "toml" in kinds


@pytest.fixture(scope="module")
def fresh(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fresh")
    shutil.copytree(ROOT / "examples", folder / "examples")
    return folder


def test_readme_examples_run_in_order(fresh, monkeypatch):
    monkeypatch.chdir(fresh)
    session: dict = {}
    for k, (lang, body) in enumerate(blocks()):
        if is_ci(body):
            continue
        if lang == "python":
            exec(compile(body, f"README python block {k}", "exec"), session)
        elif lang == "bash":
            done = subprocess.run(
                ["bash", "-euo", "pipefail", "-c", body], cwd=fresh, capture_output=True, text=True
            )
            assert done.returncode == 0, f"README bash block {k}:\n{body}\n{done.stderr}"
        elif lang == "toml":
            path = fresh / f"block{k}.toml"
            path.write_text(body)
            robot = cc.load_robot(path)
            assert robot.dof >= 1
    assert (fresh / "out").is_dir()  # outputs went where .gitignore covers them


def test_readme_robot_file_example_means_what_it_says(tmp_path):
    toml = next(body for lang, body in blocks() if lang == "toml")
    path = tmp_path / "arm.toml"
    path.write_text(toml)
    robot = cc.load_robot(path)
    assert robot.tool.xyz[2] == pytest.approx(0.1)  # 100 mm under length_unit = "mm"
