"""The command line as a package (issue 24): no import circle, modules of a readable
size, and each new command and option driven through the installed entry point
(``python -m casecal`` and the ``casecal`` script): ``convert``, ``-q``, ``-v``,
``--package`` and the help texts.
"""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import casecal as cc

CLI = Path(cc.__file__).parent / "cli"


def casecal(*argv, script: bool = False) -> subprocess.CompletedProcess:
    """Run the installed command in a fresh process: (exit code, stdout, stderr)."""
    head = [shutil.which("casecal")] if script else [sys.executable, "-m", "casecal"]
    return subprocess.run([*head, *map(str, argv)], capture_output=True, text=True)


def _imports(path: Path) -> set[str]:
    """The sibling modules of casecal.cli that `path` imports (at any depth of the code)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module:
                found.add(node.module.split(".")[0])
            else:
                found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("casecal.cli"):
            found.add([*node.module.split("."), "__init__"][2])
    return found


def test_the_cli_modules_import_each_other_without_a_circle():
    graph = {p.stem: _imports(p) for p in CLI.glob("*.py")}
    assert {"main", "common", "convert", "identify"} <= set(graph)
    for module, imported in graph.items():
        assert imported <= set(graph), (module, imported)
        if module not in ("__init__", "__main__"):  # only they gather the commands
            assert not imported & {"__init__", "main"}, module
    done: set[str] = set()

    def visit(module: str, path: tuple[str, ...]) -> None:
        assert module not in path, f"import circle: {' -> '.join((*path, module))}"
        if module not in done:
            for other in graph[module]:
                visit(other, (*path, module))
            done.add(module)

    for module in graph:
        visit(module, ())
    for command in ("compare", "compensate", "convert", "identify", "show", "simulate"):
        assert graph[command] <= {"argtypes", "common", "writing", "identify_modes"}, command


def test_the_cli_modules_are_of_a_readable_size():
    sizes = {p.name: len(p.read_text().splitlines()) for p in CLI.glob("*.py")}
    assert max(sizes.values()) <= 300, sizes


def test_the_old_import_paths_still_answer():
    from casecal.cli import build_parser, main, parse_length
    from casecal.cli.main import main as main_too

    assert main is main_too and callable(build_parser) and parse_length("1mm") == 1e-3
    done = subprocess.run(
        [sys.executable, "-m", "casecal.cli", "--version"], capture_output=True, text=True
    )
    assert done.returncode == 0 and done.stdout.startswith("casecal ")


@pytest.mark.parametrize("robot", ["rx90b_mdh", "scara"])
def test_convert_round_trips_toml_urdf_toml_exactly(tmp_path, robot):
    first, urdf, back = tmp_path / "a.toml", tmp_path / "a.urdf", tmp_path / "b.toml"
    for src, out in ((robot, first), (first, urdf), (urdf, back)):
        done = casecal("convert", src, out)
        assert done.returncode == 0, done.stderr
        assert "warning" not in done.stderr and str(out) in done.stdout
    nominal = cc.load_robot(robot)
    q = cc.poses.uniform(nominal, 200, seed=3)
    for path in (first, urdf, back):
        got = cc.load_robot(path).measured_points(q)
        assert np.max(np.abs(got - nominal.measured_points(q))) < 1e-12, path


def test_convert_to_a_ur_kinematics_file_and_back(tmp_path):
    yaml, toml = tmp_path / "ur.yaml", tmp_path / "ur.toml"
    assert casecal("convert", "ur5e", yaml).returncode == 0
    assert casecal("convert", yaml, toml).returncode == 0
    nominal = cc.load_robot("ur5e")
    q = cc.poses.uniform(nominal, 100, seed=4)
    got = cc.load_robot(toml).measured_points(q)
    assert np.max(np.abs(got - nominal.measured_points(q))) < 1e-12


def test_convert_never_replaces_the_file_it_reads(tmp_path):
    mine = tmp_path / "mine.toml"
    assert casecal("convert", "rr", mine).returncode == 0
    text = mine.read_text() + "# the user's own notes\n"
    mine.write_text(text)
    link = tmp_path / "link.toml"
    link.symlink_to(mine)
    for out in (mine, link):
        done = casecal("convert", mine, out)
        assert done.returncode == 2 and done.stderr.count("\n") == 1
        assert done.stderr.startswith("casecal: error: OUT ")
        assert "replace that input" in done.stderr
    assert mine.read_text() == text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.toml", "mine.toml"]


COUPLED = """\
name = "coupled"
convention = "dh"
length_unit = "mm"
angle_unit = "deg"
[[joints]]
type = "R"
a = 100.0
alpha = 0.0
d = 0.0
[[joints]]
type = "R"
a = 80.0
alpha = 0.0
d = 0.0
[coupling]
controller_joints = 1
q2 = {q1 = -1.0}
"""


def test_convert_refuses_what_the_format_cannot_hold(tmp_path):
    robot = tmp_path / "coupled.toml"
    robot.write_text(COUPLED)
    done = casecal("convert", robot, tmp_path / "coupled.urdf")
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert "couples its joints" in done.stderr and "save as .toml" in done.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["coupled.toml"]


def _measured(tmp_path: Path) -> Path:
    csv = tmp_path / "m.csv"
    done = casecal("-q", "simulate", "puma560", "--poses", "30", "--schedule", "uniform",
                   "--noise", "0.01mm", "-o", csv)  # fmt: skip
    assert done.returncode == 0 and done.stdout == "" and done.stderr == "", done
    return csv


def test_quiet_prints_only_the_requested_outputs(tmp_path):
    csv = _measured(tmp_path)
    out = tmp_path / "cal.urdf"
    done = casecal("identify", "puma560", csv, "-o", out, "-q")
    assert done.returncode == 0, done.stderr
    assert done.stdout == "" and done.stderr == "" and out.is_file()
    piped = casecal("simulate", "rr", "--poses", "2", "-o", "/dev/stdout", "--quiet")
    assert piped.returncode == 0 and piped.stderr == "", piped.stderr
    assert piped.stdout.splitlines()[0] == "q1_deg,q2_deg,x_mm,y_mm,z_mm"
    assert len(piped.stdout.splitlines()) == 3
    loud = casecal("identify", "puma560", csv)
    assert "casecal calibration results" in loud.stdout
    # a command whose table is the requested output still prints it
    assert "puma560" in casecal("-q", "robots").stdout
    both = casecal("-q", "robots", "-v")
    assert both.returncode == 2 and "-q (quiet) and -v (verbose)" in both.stderr


def test_verbose_shows_the_progress_of_a_small_fit(tmp_path):
    csv = _measured(tmp_path)
    quiet = casecal("identify", "puma560", csv)
    assert "iteration" not in quiet.stderr
    for argv in (("-v", "identify", "puma560", csv), ("identify", "puma560", csv, "-v")):
        done = casecal(*argv)
        assert done.returncode == 0, done.stderr
        lines = done.stderr.splitlines()
        assert any(ln.startswith("casecal: 30 poses, round 1, iteration 1: RMS") for ln in lines)
        assert "casecal: INFO: robot puma560 from puma560: 6 joints (dh)" in lines


ARM = """\
<?xml version="1.0"?>
<robot xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:macro name="arm">
    <link name="base"/>
    <link name="l1">
      <visual><geometry><mesh filename="package://my_arm/meshes/l1.stl"/></geometry></visual>
    </link>
    <link name="tip"/>
    <joint name="j1" type="revolute">
      <parent link="base"/><child link="l1"/><origin xyz="0 0 0.3" rpy="0 0 0"/>
      <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/>
    </joint>
    <joint name="j2" type="revolute">
      <parent link="l1"/><child link="tip"/><origin xyz="0.25 0 0" rpy="0 0 0"/>
      <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/>
    </joint>
  </xacro:macro>
</robot>
"""

TOP = """\
<?xml version="1.0"?>
<robot name="two" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:include filename="$(find my_arm)/urdf/arm.xacro"/>
  <xacro:arm/>
</robot>
"""


def test_package_resolves_a_xacro_include_and_its_meshes(tmp_path):
    pytest.importorskip("xacrodoc")
    package = tmp_path / "ws" / "my_arm"
    (package / "urdf").mkdir(parents=True)
    (package / "urdf" / "arm.xacro").write_text(ARM)
    (tmp_path / "robot").mkdir()
    top = tmp_path / "robot" / "two.urdf.xacro"
    top.write_text(TOP)
    lost = casecal("show", top)
    assert lost.returncode == 2 and lost.stderr.count("\n") == 1
    assert "--package NAME=PATH" in lost.stderr
    shown = casecal("show", top, "--package", f"my_arm={package}")
    assert shown.returncode == 0, shown.stderr
    assert "300.0000" in shown.stdout and "250.0000" in shown.stdout
    out = tmp_path / "two.urdf"
    done = casecal("convert", top, out, "--package", f"my_arm={package}")
    assert done.returncode == 0, done.stderr
    assert f"file://{package}/meshes/l1.stl" in out.read_text()
    bad = casecal("show", top, "--package", f"my_arm={tmp_path / 'nowhere'}")
    assert bad.returncode == 2 and "is not a folder" in bad.stderr
    assert bad.stderr.count("\n") == 1
    assert casecal("show", top, "--package", "my_arm").returncode == 2


def test_help_says_what_each_command_takes():
    top = casecal("--help", script=shutil.which("casecal") is not None)
    assert top.returncode == 0 and "convert" in top.stdout and "--quiet" in top.stdout
    identify = casecal("identify", "--help").stdout
    for text in (".toml", ".urdf", ".yaml", "--base-link", "--package", "--verbose"):
        assert text in identify, text
    for command in ("robots", "report"):
        text = casecal(command, "--help").stdout
        assert "--base-link" not in text and "--package" not in text, command
    convert = casecal("convert", "--help").stdout
    assert "IN" in convert and "OUT" in convert and "--package" in convert
    assert casecal("robots", "--base-link", "x").returncode == 2


def test_the_console_script_runs_convert(tmp_path):
    if shutil.which("casecal") is None:
        pytest.skip("no casecal script on PATH")
    out = tmp_path / "rr.urdf"
    done = casecal("convert", "rr", out, script=True)
    assert done.returncode == 0 and out.is_file(), done.stderr
    assert os.path.getsize(out) > 0


def test_convert_keeps_the_link_to_the_nominal_robot_from_the_new_folder(tmp_path):
    """A calibrated robot converted into another folder still names its own nominal robot
    (calibrated_from, relative to the file), not the path copied as it was, which would be
    read from the new folder (here a decoy: another robot at b/a/nominal.toml)."""
    a, b = tmp_path / "a", tmp_path / "b"
    (b / "a").mkdir(parents=True)
    a.mkdir()
    assert casecal("convert", "rr", a / "nominal.toml").returncode == 0
    assert casecal("convert", "puma560", b / "a" / "nominal.toml").returncode == 0
    text = (a / "nominal.toml").read_text()
    (a / "cal.toml").write_text('calibrated_from = "nominal.toml"\n' + text)
    done = subprocess.run(  # relative paths, as typed: loading makes the link "a/nominal.toml"
        [sys.executable, "-m", "casecal", "convert", "a/cal.toml", "b/cal.toml"],
        cwd=tmp_path, capture_output=True, text=True,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert 'calibrated_from = "../a/nominal.toml"' in (b / "cal.toml").read_text()
    link = cc.load_robot(str(b / "cal.toml")).calibrated_from
    assert Path(link).resolve() == (a / "nominal.toml").resolve()
