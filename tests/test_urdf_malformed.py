"""Issue 20 findings 6, 8 and 16 (URDF): malformed URDF structures end in one line.

Each case runs `casecal show FILE.urdf` and must exit 2 with one ``casecal: error:`` line
naming the cause. The closed loops (which once grew memory without end) run in a child
process with a time and a memory limit, the rest in this process under an alarm, so that
a regression fails instead of hanging the suite.
"""

from __future__ import annotations

import resource
import signal
import subprocess
import sys

import numpy as np
import pytest

import casecal as cc
from casecal.cli import main

LIMIT_S = 60
MEMORY = 1 << 30  # bytes: far above what `show` needs (under 300 MB), far below a runaway


def _link(name: str) -> str:
    return f'<link name="{name}"/>'


def _joint(name, parent, child, kind="revolute", extra="", limit=True) -> str:
    lim = '<limit lower="-3" upper="3" effort="1" velocity="1"/>' if limit else ""
    if kind != "revolute":
        lim = ""
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
        f'<child link="{child}"/>{extra}{lim}</joint>'
    )


def _robot(links, joints) -> str:
    body = "".join(_link(n) for n in links) + "".join(joints)
    return f'<?xml version="1.0"?>\n<robot name="bad">{body}</robot>\n'


ARM = ["b", "l1", "l2", "l3", "l4", "l5"]
BASE = [_joint("j1", "b", "l1"), _joint("j2", "l1", "l2")]  # then joints hanging off l2
LOOP3 = [("l2", "l3"), ("l3", "l4"), ("l4", "l2")]


def _fixed_chain(n: int) -> str:
    links = [f"f{i}" for i in range(n + 1)]
    return _robot(links, [_joint(f"k{i}", f"f{i}", f"f{i + 1}", "fixed") for i in range(n)])


def _origin(xyz="0 0 0", rpy="0 0 0") -> str:
    return _robot(
        ["b", "l1"], [_joint("j1", "b", "l1", extra=f'<origin xyz="{xyz}" rpy="{rpy}"/>')]
    )


def _limits(lower, upper, kind="revolute") -> str:
    lim = f'<limit lower="{lower}" upper="{upper}" effort="1" velocity="1"/>'
    return _robot(
        ["b", "l1", "l2"],
        [
            _joint("j1", "b", "l1"),
            f'<joint name="elbow" type="{kind}"><parent link="l1"/><child link="l2"/>'
            f'<axis xyz="0 0 1"/>{lim}</joint>',
        ],
    )


def _axis(axis_element: str) -> str:
    return _robot(
        ["b", "l1"],
        [
            '<joint name="j1" type="continuous"><parent link="b"/><child link="l1"/>'
            f"{axis_element}</joint>"
        ],
    )


CASES = {
    # closed loops: before, `show` never returned and memory grew (2 GB in two minutes)
    "loop of 1 (self-parent on a chain)": (
        _robot(ARM, [*BASE, _joint("j3", "l2", "l2"), _joint("j4", "l2", "l3")]),
        ["closed loop", "l2 -> l2"],
    ),
    "loop: a self-parent joint alone": (
        _robot(["a"], [_joint("j", "a", "a")]),
        ["closed loop", "a"],
    ),
    "loop of 2": (
        _robot(
            ARM,
            [*BASE, _joint("j3", "l2", "l3"), _joint("j4", "l3", "l2"), _joint("j5", "l3", "l4")],
        ),
        ["closed loop", "l2 -> l3 -> l2"],
    ),
    "loop of 3": (
        _robot(
            ARM,
            [
                *BASE,
                *(_joint(f"j{i}", p, c) for i, (p, c) in enumerate(LOOP3, start=3)),
                _joint("j6", "l4", "l5"),
            ],
        ),
        ["closed loop", "l2 -> l3 -> l4 -> l2"],
    ),
    "loop without a root": (
        _robot(["p", "q"], [_joint("jp", "p", "q"), _joint("jq", "q", "p")]),
        ["closed loop", "p", "q"],
    ),
    # before: loaded silently as a shorter robot (the last joint won)
    "two parents": (
        _robot(
            ARM,
            [*BASE, _joint("ja", "l2", "l4"), _joint("j3", "l2", "l3"), _joint("jb", "l3", "l4")],
        ),
        ["'l4'", "two parent joints", "'ja'", "'jb'", "tree"],
    ),
    "two roots": (
        _robot(["b", "l1", "c", "l2"], [_joint("j1", "b", "l1"), _joint("j2", "c", "l2")]),
        ["several root links (b, c)", "--base-link"],
    ),
    "missing child link": (
        _robot(["b", "l1"], [_joint("j1", "b", "l1"), _joint("j2", "l1", "ghost")]),
        ["'j2'", "'ghost'", "<link"],
    ),
    "missing parent link": (
        _robot(["b", "l1"], [_joint("j1", "nowhere", "l1")]),
        ["'j1'", "'nowhere'", "<link"],
    ),
    "joint without parent": (
        _robot(
            ["b", "l1", "l2"],
            [_joint("j1", "b", "l1"), '<joint name="j2" type="fixed"><child link="l2"/></joint>'],
        ),
        ["'j2'", "<parent"],
    ),
    "duplicate joint names": (
        _robot(["b", "l1", "l2"], [_joint("j1", "b", "l1"), _joint("j1", "l1", "l2")]),
        ["joint 'j1'", "twice"],
    ),
    "duplicate link names": (
        _robot(["b", "l1", "l1"], [_joint("j1", "b", "l1")]),
        ["link 'l1'", "twice"],
    ),
    "origin xyz of two numbers": (_origin(xyz="1 2"), ["'j1'", "origin xyz", "'1 2'"]),
    "origin xyz not numbers": (_origin(xyz="a b c"), ["'j1'", "origin xyz", "'a b c'"]),
    "origin xyz nan": (_origin(xyz="nan 0 0"), ["'j1'", "origin xyz", "'nan 0 0'"]),
    "origin rpy inf": (_origin(rpy="0 inf 0"), ["'j1'", "origin rpy", "'0 inf 0'"]),
    # before: loaded, then `simulate --schedule uniform` died with a numpy traceback
    "revolute limits reversed": (_limits("1.5", "-0.5"), ["'elbow'", "85.9437", "-28.6479"]),
    "prismatic limits reversed": (
        _limits("0.2", "0.1", "prismatic"),
        ["'elbow'", "200 mm", "100 mm"],
    ),
    "limit nan": (_limits("nan", "1"), ["'elbow'", "lower limit", "'nan'"]),
    "limit inf": (_limits("-1", "inf"), ["'elbow'", "upper limit", "'inf'"]),
    "axis zero": (_axis('<axis xyz="0 0 0"/>'), ["'j1'", "axis", "zero"]),
    "axis without xyz": (_axis("<axis/>"), ["'j1'", "<axis", "xyz"]),
    "axis of two numbers": (_axis('<axis xyz="0 1"/>'), ["'j1'", "axis"]),
    # finding 16: say what is wrong, in command-line terms
    "no joints": (_robot(["b"], []), ["no joints", "nothing moves"]),
    "only fixed joints": (
        _robot(["b", "l1"], [_joint("j1", "b", "l1", "fixed")]),
        ["no movable joint", "only fixed"],
    ),
    "2000 fixed joints": (_fixed_chain(2000), ["no movable joint", "only fixed"]),
    "empty file": ("", ["empty"]),
    "blank file": ("\n  \n", ["empty"]),
    "not XML": ("this is not xml {", ["not valid XML"]),
    "XML that is not a robot": ('<sdf version="1.6"><model name="m"/></sdf>', ["<sdf>", "<robot>"]),
    "deeply nested XML": (
        "<robot>" + "<a>" * 5000 + "</a>" * 5000 + "</robot>",
        ["no joints", "nothing moves"],
    ),
    "entity expansion": (
        '<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaaaaaaaa">'
        + "".join(
            f'<!ENTITY {c} "{("&" + p + ";") * 10}">'
            for p, c in zip("abcdefgh", "bcdefghi", strict=True)
        )
        + ']><robot name="&i;"/>',
        ["XML"],
    ),
}


def _limited():  # in the child: a memory ceiling, so that a runaway fails fast
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY, MEMORY))


def _in_child(path) -> tuple[int, str]:
    """`casecal show PATH` in a child with a time and a memory limit."""
    run = subprocess.run(
        [sys.executable, "-m", "casecal", "show", str(path)],
        capture_output=True,
        text=True,
        timeout=LIMIT_S,
        preexec_fn=_limited,
    )
    return run.returncode, run.stderr


def _in_process(path, capsys) -> tuple[int, str]:
    """`casecal show PATH` here, under an alarm: a hang fails the test, not the suite."""

    def expired(signum, frame):
        raise TimeoutError(f"casecal show did not return within {LIMIT_S} s")

    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(LIMIT_S)
    try:
        code = main(["show", str(path)])
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    return code, capsys.readouterr().err


@pytest.mark.parametrize("case", list(CASES))
def test_malformed_urdf_is_one_line_and_exit_2(tmp_path, capsys, case):
    text, needles = CASES[case]
    path = tmp_path / "bad.urdf"
    path.write_text(text)
    # loops once grew memory without end: those run where a memory limit can hold them
    code, err = (_in_child if "loop" in case else lambda p: _in_process(p, capsys))(path)
    assert "Traceback" not in err, err
    assert code == 2, (code, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("casecal: error: "), err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


def test_a_long_fixed_chain_before_one_joint_loads(tmp_path):
    """2000 fixed joints fold into the one movable joint's origin: no recursion, no limit."""
    n = 2000
    links = [f"f{i}" for i in range(n + 1)] + ["tip"]
    step = '<origin xyz="0.001 0 0" rpy="0 0 0"/>'
    joints = [_joint(f"k{i}", f"f{i}", f"f{i + 1}", "fixed", step) for i in range(n)]
    joints.append(_joint("j", f"f{n}", "tip", "continuous"))
    (tmp_path / "long.urdf").write_text(_robot(links, joints))
    robot = cc.load_robot(tmp_path / "long.urdf")
    assert robot.dof == 1
    assert np.allclose(robot.fk(np.zeros(1))[:3, 3], [n * 0.001, 0, 0])


def test_equal_limits_are_a_locked_joint_not_an_error(tmp_path):
    """URDF allows lower == upper (a joint held still); only lower > upper is refused."""
    (tmp_path / "eq.urdf").write_text(_limits("0.5", "0.5"))
    robot = cc.load_robot(tmp_path / "eq.urdf")
    assert robot.joints[1].limits == (0.5, 0.5)
