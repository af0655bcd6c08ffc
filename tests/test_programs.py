"""Program compensation (casecal.programs): hand-written KRL, RAPID, URScript and CSV
programs, with comments, odd spacing and unrelated lines, compensated for a catalog robot
with known deviations. Only the target values change; the new targets reach the nominal
poses on the calibrated robot; unreadable targets are refused with their line."""

from __future__ import annotations

import doctest
import re

import numpy as np
import pytest

import casecal as cc
import casecal.programs
from casecal.data.files import read_joints
from casecal.data.table import read_table
from casecal.programs import (
    calibration_header,
    compensate_program,
    krl,
    program_format,
    rapid,
    urscript,
)

HEADER = "calibrated.toml (sha256 0123456789ab), audit: passed"
NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
REACH = 3.0  # m: more than any of these arms' lever from a joint to the tool

KRL_DAT = (
    "&ACCESS RVP\r\n"
    "&REL 3\r\n"
    "&PARAM EDITMASK = *\r\n"
    "DEFDAT  WELD_CELL\r\n"
    ";FOLD EXTERNAL DECLARATIONS;%{PE}%MKUKATPBASIS,%CEXT,%VCOMMON,%P\r\n"
    "EXT  BAS (BAS_COMMAND  :IN,REAL  :IN )\r\n"
    ";ENDFOLD (EXTERNAL DECLARATIONS)\r\n"
    'DECL BASIS_SUGG_T LAST_BASIS={POINT1[] "P0   ",CP_VEL[] "2.0  ",PTP_VEL[] "100 "}\r\n'
    "DECL E6AXIS XP1={A1 10.0,A2 -20.0,A3 -95.0,A4 5.0,A5 30.0,A6 -12.5,E1 0.0,E2 0.0,"
    "E3 0.0,E4 0.0,E5 0.0,E6 0.0}\r\n"
    'DECL FDAT FP1={TOOL_NO 1,BASE_NO 0,IPO_FRAME #BASE,POINT2[] " ",TQ_STATE FALSE}\r\n'
    "DECL PDAT PPDAT1={VEL 100.000,ACC 100.000,APO_DIST 100.000,APO_MODE #CDIS}\r\n"
    "DECL E6AXIS XP2={A1 -35.25,A2  10.5 ,A3 -110.125,A4 -20.0,A5 45.75,A6 90.0,"
    "E1 1250.5,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}   ; approach {A1 1,A2 2}\r\n"
    "DECL E6POS XP3={X 1200.0,Y 0.0,Z 1500.0,A 0.0,B 90.0,C 0.0,S 2,T 35,E1 0.0}\r\n"
    "DECL AXIS HOME={A1 0.0,A2 -90.0,A3 90.0,A4 0.0,A5 0.0,A6 0.0}\r\n"
    "\tDECL GLOBAL E6AXIS XP4={A1 190.0,A2 20.0,A3 -100.0,A4 0.0,A5 40.0,A6 0.0,E1 0.0}\r\n"
    "ENDDAT\r\n"
)
KRL_DAT_TARGETS = {  # line: degrees
    9: [10.0, -20.0, -95.0, 5.0, 30.0, -12.5],
    12: [-35.25, 10.5, -110.125, -20.0, 45.75, 90.0],
    14: [0.0, -90.0, 90.0, 0.0, 0.0, 0.0],
    15: [190.0, 20.0, -100.0, 0.0, 40.0, 0.0],
}

KRL_SRC = """&ACCESS RVP
&REL 3
DEF weld_cell( )
;FOLD INI;%{PE}
  ;FOLD BASISTECH INI
    GLOBAL INTERRUPT DECL 3 WHEN $STOPMESS==TRUE DO IR_STOPM ( )
    INTERRUPT ON 3
    BAS (#INITMOV,0 )
  ;ENDFOLD (BASISTECH INI)
;ENDFOLD (INI)

;FOLD PTP HOME  Vel= 100 % DEFAULT;%{PE}%MKUKATPBASIS,%CMOVE,%VPTP,%P 1:PTP, 2:HOME
$BWDSTART = FALSE
PTP  XHOME
;ENDFOLD
PTP {A1 10, A2 15.5, A3 -100, A4 0, A5 35, A6 0}   ; inline, odd spacing
\tPTP {A1 -20.0,A2 30.0,A3 -80.0,A4 15.0,A5 -40.0,A6 25.0, E1 300.0}
PTP {E6AXIS: A1 5.0,A2 -50.0,A3 -95.0,A4 0.0,A5 45.0,A6 0.0} C_PTP
;PTP {A1 0, A2 0, A3 0, A4 0, A5 0, A6 0}  commented out: untouched
PTP_REL {A1 10}
PTP {A3 45}
LIN XP3
PTP XP1
END
"""
KRL_SRC_TARGETS = {
    16: [10, 15.5, -100, 0, 35, 0],
    17: [-20.0, 30.0, -80.0, 15.0, -40.0, 25.0],
    18: [5.0, -50.0, -95.0, 0.0, 45.0, 0.0],
}

RAPID_MOD = """MODULE MainModule
    ! hand-written cell program
    CONST jointtarget jt1:=[[0,-30,30,0,45,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
    PERS jointtarget jt2 := [ [ 12.5 , 20 , -15.25 , 30 , -60 , 90 ] ,
                              [ 1500 , 9E+09 , 9E+09 , 9E+09 , 9E+09 , 9E+09 ] ] ;
    LOCAL CONST jointtarget jt3:=[[-40,10,20,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
    CONST jointtarget park{2}:=[[[90,-20,40,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]],
                                [[-90,-20,40,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]]];
    CONST robtarget p10:=[[500,0,600],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
    VAR jointtarget jt4;
    CONST jointtarget jt5:=jt1;
    CONST speeddata vslow:=[100,50,5000,1000];

    PROC main()
        MoveAbsJ jt1\\NoEOffs, v1000, z50, tool0;
        MoveAbsJ [[25,-10,15,5,50,-5],[9E9,9E9,9E9,9E9,9E9,9E9]]\\NoEOffs, vslow, fine, tool0;
        MoveAbsJ jt2, [100,50,5000,1000], fine, tool0;  ! a speeddata literal: no target
        jt4 := [[-10,5,10,0,60,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
        jt4 := CalcJointT(p10, tool0);
        MoveJ p10, v500, z10, tool0;
        TPWrite "MoveAbsJ [[1,2,3,4,5,6],[0,0,0,0,0,0]];";
    ENDPROC
ENDMODULE
"""
RAPID_TARGETS = {
    3: [0, -30, 30, 0, 45, 0],
    4: [12.5, 20, -15.25, 30, -60, 90],
    6: [-40, 10, 20, 0, 0, 0],
    7: [90, -20, 40, 0, 30, 0],
    8: [-90, -20, 40, 0, 30, 0],
    16: [25, -10, 15, 5, 50, -5],
    18: [-10, 5, 10, 0, 60, 0],
}

URSCRIPT = """def cell_program():
  # pick and place, joint moves
  set_tcp(p[0, 0, 0.1, 0, 0, 0])
  global home_q = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
  approach = [ 0.35 ,-1.1,  1.4, -1.9 , -1.55, 0.4 ]   # odd spacing
  movej(home_q, a=1.4, v=1.05)
  movej([0.1, -1.2, 1.3, -1.7, -1.5, 0.2], a=1.2, v=0.25)
  movej(approach, a=1.2, v=0.25, r=0.02)
  movel([-0.4, -1.3, 1.2, -1.4, -1.6, -0.3], a=0.5, v=0.1)
  movej([d2r(30), d2r(-80), d2r(70), d2r(-80), d2r(-90), d2r(0)], a=1.2, v=0.25)
  movel(p[0.4, -0.1, 0.3, 0, 3.14, 0], a=0.5, v=0.1)
  movej(get_inverse_kin(p[0.4, 0.1, 0.3, 0, 3.14, 0]), a=1.2, v=0.25)
  textmsg("movej([1, 2, 3, 4, 5, 6])")
end
"""
URSCRIPT_TARGETS = {
    4: [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0],
    5: [0.35, -1.1, 1.4, -1.9, -1.55, 0.4],
    7: [0.1, -1.2, 1.3, -1.7, -1.5, 0.2],
    9: [-0.4, -1.3, 1.2, -1.4, -1.6, -0.3],
    10: list(np.deg2rad([30, -80, 70, -80, -90, 0])),
}

CSV = (
    "name,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,speed\r\n"
    "p1,10.0,-20.0,-95.0,5.0,30.0,-12.5,100\r\n"
    'p2, -35.25 ,10.5,-110.125,-20.0,45.75,"90.0",50\r\n'
    "p3,190,20,-100,0,40,0,100\r\n"
)
CSV_TARGETS = {2: KRL_DAT_TARGETS[9], 3: KRL_DAT_TARGETS[12], 4: KRL_DAT_TARGETS[15]}


def kuka():
    nominal = cc.load_robot("kr16_2")
    real = nominal.with_deviations(
        {"a1": 1.5e-4, "a2": 3e-4, "alpha2": 3e-4, "theta3": 5e-4, "d4": -2e-4, "theta5": -4e-4}
    )
    return nominal, real


def abb():
    nominal = cc.load_robot("irb140")
    real = nominal.with_deviations(
        {"a2": -2.5e-4, "theta2": 3e-4, "beta2": 2e-4, "d4": 4e-4, "theta4": -6e-4}
    )
    return nominal, real


def ur():
    nominal = cc.load_robot("ur5e")
    real = nominal.with_deviations(
        {"a2": 4e-4, "a3": -3e-4, "theta2": 2e-4, "alpha3": 5e-4, "d4": 1e-4}
    )
    return nominal, real


def body(out: str) -> str:
    """The output without its header comment line."""
    lines = out.splitlines(keepends=True)
    marked = [k for k, line in enumerate(lines) if "compensated by casecal" in line]
    assert len(marked) == 1
    return "".join(lines[: marked[0]] + lines[marked[0] + 1 :])


def check_only_targets_changed(source: str, out: str, changed: set[int], bound: float):
    """Line by line (line endings included): lines without a compensated target are
    identical; on the others only numbers differ, each by less than `bound`."""
    old, new = source.splitlines(keepends=True), out.splitlines(keepends=True)
    assert len(old) == len(new)
    for line, (a, b) in enumerate(zip(old, new, strict=True), start=1):
        if line not in changed:
            assert a == b, line
            continue
        assert NUMBER.split(a) == NUMBER.split(b), line  # the text between the numbers
        x, y = NUMBER.findall(a), NUMBER.findall(b)
        moved = [abs(float(p) - float(q)) for p, q in zip(x, y, strict=True) if p != q]
        assert 0 < len(moved) <= 6 and max(moved) < bound, line


def check_targets(module, source, robot, expected, scale):
    """The parser finds exactly the hand-listed targets (value, line)."""
    found = module.find(source, robot)
    assert {t.line: list(t.q) for t in found.targets} == pytest.approx(
        {line: list(np.asarray(v, float) * scale) for line, v in expected.items()}
    )
    return found


def check_reached(out_q, in_q, nominal, real, result, decimals_rad):
    """The written targets take the calibrated robot where the nominal one goes at the
    input targets (the robot frame: through compensate's registration), to within what the
    written decimals' rounding can move the tool, and agree with `casecal.compensate`."""
    X = result.compensation.registration
    want = (X @ nominal.fk(in_q))[:, :3, 3]
    got = real.position(out_q)
    bound = in_q.shape[1] * 0.5 * 10.0**-decimals_rad * REACH + 2e-9
    assert bound < 1e-6
    assert np.max(np.linalg.norm(got - want, axis=1)) < bound
    direct = cc.compensate(real, in_q, nominal=nominal)
    assert np.allclose(out_q, direct.q[direct.ok], atol=0.51 * 10.0**-decimals_rad)


def test_krl_datalist_compensated_only_its_joint_values():
    nominal, real = kuka()
    check_targets(krl, KRL_DAT, nominal, KRL_DAT_TARGETS, np.pi / 180)
    result = compensate_program(real, KRL_DAT, "krl", nominal=nominal, header=HEADER)
    assert result.changed == (9, 12)
    lines = dict(result.skipped)
    assert "Cartesian" in lines[13]
    assert "outside the limits of joint 2" in lines[14]  # HOME's A2 -90 is outside
    assert "outside the limits of joint 1" in lines[15]  # A1 190 beyond 185
    assert result.text.splitlines()[4] == f"; compensated by casecal: {HEADER}"
    assert result.text.count("\r\n") == KRL_DAT.count("\r\n") + 1
    check_only_targets_changed(KRL_DAT, body(result.text), {9, 12}, 0.5)
    assert "E1 1250.5,E2 0.0" in result.text and "approach {A1 1,A2 2}" in result.text
    again = krl.find(body(result.text), nominal)  # round trip: the output parses
    out_q = np.array([t.q for t in again.targets if t.line in (9, 12)])
    in_q = np.deg2rad([KRL_DAT_TARGETS[9], KRL_DAT_TARGETS[12]])
    check_reached(out_q, in_q, nominal, real, result, 6 + np.log10(180 / np.pi))


def test_krl_src_inline_targets_and_what_is_left():
    nominal, real = kuka()
    check_targets(krl, KRL_SRC, nominal, KRL_SRC_TARGETS, np.pi / 180)
    result = compensate_program(real, KRL_SRC, "krl", nominal=nominal, header=HEADER)
    assert result.changed == (16, 17, 18)
    assert [line for line, _ in result.skipped] == [20, 21]
    assert "relative" in result.skipped[0][1] and "no A1" in result.skipped[1][1]
    assert result.text.splitlines()[3] == f"; compensated by casecal: {HEADER}"
    check_only_targets_changed(KRL_SRC, body(result.text), {16, 17, 18}, 0.5)
    assert "\tPTP {A1 " in result.text and ", E1 300.0}" in result.text
    assert "C_PTP\n;PTP {A1 0, A2 0, A3 0, A4 0, A5 0, A6 0}  commented" in result.text
    in_q = np.deg2rad(list(KRL_SRC_TARGETS.values()))
    out_q = np.array([t.q for t in krl.find(body(result.text), nominal).targets])
    check_reached(out_q, in_q, nominal, real, result, 6 + np.log10(180 / np.pi))


def test_rapid_module_compensated_only_its_joint_values():
    nominal, real = abb()
    check_targets(rapid, RAPID_MOD, nominal, RAPID_TARGETS, np.pi / 180)
    result = compensate_program(real, RAPID_MOD, "rapid", nominal=nominal, header=HEADER)
    lines = dict(result.skipped)
    assert "singularity" in lines[6]  # joint 5 at 0: a wrist singularity
    assert "robtarget" in lines[9] and "CalcJointT" in lines[19]
    changed = set(RAPID_TARGETS) - {6}
    assert set(result.changed) == changed
    assert result.text.splitlines()[1] == f"    ! compensated by casecal: {HEADER}"
    check_only_targets_changed(RAPID_MOD, body(result.text), changed, 0.5)
    assert result.text.count("9E9") == RAPID_MOD.count("9E9")
    assert "[ 1500 , 9E+09 , 9E+09" in result.text and "[100,50,5000,1000]" in result.text
    ok = [line for line in RAPID_TARGETS if line in changed]
    out_q = np.array([t.q for t in rapid.find(body(result.text), nominal).targets if t.line in ok])
    in_q = np.deg2rad([RAPID_TARGETS[line] for line in ok])
    check_reached(out_q, in_q, nominal, real, result, 6 + np.log10(180 / np.pi))


def test_rapid_statements_after_block_headers():
    """A routine's header (no ';') before a statement does not hide the statement's
    target; a position computed at run time is listed; reading a part of a target is no
    assignment to it."""
    nominal, real = abb()
    text = (
        "MODULE Extra\n"
        "    PROC MoveToHome(VAR jointtarget jt)\n"
        "        MoveAbsJ [[10,20,30,0,40,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, fine, tool0;\n"
        "        MoveAbsJ CalcJointT(p10, tool0)\\NoEOffs, v100, fine, tool0;\n"
        "        MoveAbsJ jt\\NoEOffs, v100, fine, tool0;\n"
        "        IF jt.robax.rax_1 > 0 THEN\n"
        '            TPWrite "ok";\n'
        "        ENDIF\n"
        "    ENDPROC\n"
        "ENDMODULE\n"
    )
    result = compensate_program(real, text, "rapid", nominal=nominal)
    assert result.changed == (3,)
    assert result.skipped == ((4, "joint values computed at run time (CalcJointT): left as is"),)


def test_urscript_compensated_only_its_joint_values():
    nominal, real = ur()
    check_targets(urscript, URSCRIPT, nominal, URSCRIPT_TARGETS, 1.0)
    result = compensate_program(real, URSCRIPT, "urscript", nominal=nominal, header=HEADER)
    assert result.changed == tuple(URSCRIPT_TARGETS)
    assert [line for line, _ in result.skipped] == [11, 12]
    assert "Cartesian" in result.skipped[0][1] and "get_inverse_kin" in result.skipped[1][1]
    assert result.text.startswith(f"# compensated by casecal: {HEADER}\ndef cell_program():\n")
    check_only_targets_changed(
        URSCRIPT, body(result.text), set(URSCRIPT_TARGETS), 0.1
    )  # rad; deg in d2r
    assert "movej([d2r(29." in result.text or "movej([d2r(30." in result.text
    assert 'textmsg("movej([1, 2, 3, 4, 5, 6])")' in result.text
    out_q = np.array([t.q for t in urscript.find(body(result.text), nominal).targets])
    in_q = np.array(list(URSCRIPT_TARGETS.values()))
    # the d2r row is written in degrees (1e-6°): the coarser of the two roundings
    check_reached(out_q, in_q, nominal, real, result, 6 + np.log10(180 / np.pi))


URSCRIPT_KEYWORDS = """def moves():
  movej(q=[0.1, -1.2, 1.3, -1.7, -1.5, 0.2], a=1.2, v=0.25)
  movej(a=1.4, v=1.05, q=[0.2, -1.1, 1.2, -1.6, -1.4, 0.1])
  movej(d2r([10, -60, 70, -30, -90, 5]), a=1.2)
  movec(pose_via=[0.3, -1.0, 1.1, -1.5, -1.5, 0.0], pose_to=p[0.4, 0, 0.3, 0, 3.14, 0], a=1)
end
"""


def test_urscript_positions_given_by_keyword_or_as_a_list_in_degrees():
    nominal, real = ur()
    expected = {
        2: [0.1, -1.2, 1.3, -1.7, -1.5, 0.2],
        3: [0.2, -1.1, 1.2, -1.6, -1.4, 0.1],
        4: list(np.deg2rad([10, -60, 70, -30, -90, 5])),
        5: [0.3, -1.0, 1.1, -1.5, -1.5, 0.0],
    }
    check_targets(urscript, URSCRIPT_KEYWORDS, nominal, expected, 1.0)
    result = compensate_program(real, URSCRIPT_KEYWORDS, "urscript", nominal=nominal)
    assert result.changed == (2, 3, 4, 5)
    assert result.skipped == ((5, "pose target p[...] (Cartesian): left as is"),)
    assert "movej(d2r([10.0" in result.text or "movej(d2r([9.9" in result.text  # degrees
    out_q = np.array([t.q for t in urscript.find(result.text, nominal).targets])
    check_reached(out_q, np.array(list(expected.values())), nominal, real, result,
                  6 + np.log10(180 / np.pi))  # fmt: skip


def test_csv_compensated_and_read_back_by_casecals_reader(tmp_path):
    nominal, real = kuka()
    result = compensate_program(real, CSV, "csv", nominal=nominal, header=HEADER)
    assert result.changed == (2, 3)
    assert [line for line, _ in result.skipped] == [4]
    assert "#" not in result.text and result.header.endswith(HEADER)  # no comment in CSV
    check_only_targets_changed(CSV, result.text, {2, 3}, 0.5)
    marked = compensate_program(real, "\ufeff" + CSV, "csv", nominal=nominal)
    assert marked.text == "\ufeff" + result.text  # a byte-order mark kept as it was
    assert "p2, -35.2" in result.text and '",50\r\n' in result.text
    path = tmp_path / "out.csv"
    path.write_bytes(result.text.encode())
    frame, label = read_table(path, "targets")  # casecal's own reader: the reference
    with pytest.warns(cc.CalibrationWarning, match="outside its limits"):  # p3: A1 190
        out_q = read_joints(frame, nominal, label)
    in_q = np.deg2rad(list(CSV_TARGETS.values()))
    assert np.array_equal(out_q[2], in_q[2])  # the failed row as it was
    direct = cc.compensate(real, in_q, nominal=nominal)
    # written exactly: nothing rounded but the degrees' conversion (a few ulp)
    assert np.allclose(out_q[:2], direct.q[:2], rtol=0, atol=1e-15)


@pytest.mark.parametrize(
    ("fmt", "text", "line", "words"),
    [
        ("krl", "DEF a()\nPTP {A1 0,A2 -90,A3 ang,A4 0,A5 30,A6 0}\nEND\n", 2, "A3 is 'ang'"),
        ("krl", "DEFDAT d\n\nDECL E6AXIS X={A1 0,A2 10+5,A3 0,A4 0,A5 1,A6 0}\n", 3, "A2"),
        ("krl", "DEF a()\nPTP {A1 0,A2 -90,A3 0\nEND\n", 2, "not closed"),
        (
            "rapid",
            "MODULE M\nCONST jointtarget j:=[[0,a,0,0,1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n",
            2,
            "axis 2",
        ),
        ("rapid", "MODULE M\n\nCONST jointtarget j:=[[0,0,0,0,1],[9E9,9E9]];\n", 3, "six values"),
        (
            "rapid",
            "MODULE M\nPROC p()\n  j.robax.rax_1 := 10;\nENDPROC\n",
            3,
            "part of a jointtarget",
        ),
        ("rapid", "MODULE M\nCONST jointtarget j:=[[0,0,0,0,1,0]];\n", 2, "must be"),
        ("urscript", "def p():\n  movej([0, -1.5, q3, 0, 1, 0])\nend\n", 2, "joint 3 is 'q3'"),
        ("urscript", "def p():\n\n  movej([0, -1.5, 1, 0, 1], a=1)\nend\n", 3, "5 values"),
        ("csv", "q1,q2,q3,q4,q5,q6\n0,0,0,0,1,0\n0,0,x,0,1,0\n", 3, "'q3' is 'x'"),
        ("csv", "q1,q2,q3,q4,q5,q6\n0,0,0,0,1,0\n\n0,0,0,0,1,0\n", 3, "blank"),
        ("csv", "q1,q2,q3,q4,q5,q6\n0,0,0,0,1\n", 2, "5 cells"),
    ],
)
def test_unreadable_target_is_refused_with_its_line(fmt, text, line, words):
    nominal, real = {"krl": kuka, "rapid": abb, "urscript": ur, "csv": kuka}[fmt]()
    with pytest.raises(cc.CalibrationError, match=rf"^line {line}: .*{re.escape(words)}"):
        compensate_program(real, text, fmt, nominal=nominal)


def test_compensating_twice_is_refused():
    nominal, real = ur()
    once = compensate_program(real, URSCRIPT, "urscript", nominal=nominal, header=HEADER)
    with pytest.raises(cc.CalibrationError, match=r"^line 1: the program was already compensated"):
        compensate_program(real, once.text, "urscript", nominal=nominal, header=HEADER)


def test_a_calibration_stands_for_its_robots_and_a_program_without_targets_is_kept():
    nominal, real = ur()
    q = cc.poses.uniform(nominal, 40, seed=0)
    cal = cc.identify(nominal, cc.simulate(real, q, noise=0.0, seed=0), ["a*", "d*"])
    text = "def p():\n  movej([0.1, -1.2, 1.3, -1.7, -1.5, 0.2], a=1.2)\nend\n"
    result = compensate_program(cal, text, "urscript")
    assert result.changed == (2,) and result.text != text
    plain = 'def p():\n  textmsg("no moves")  # nothing to do\nend\n'
    assert compensate_program(cal, plain, "urscript").text == plain


def test_format_from_the_extension_and_the_header_from_the_file(tmp_path):
    assert [program_format(f"x{e}") for e in (".src", ".DAT", ".mod", ".script", ".csv")] == [
        "krl",
        "krl",
        "rapid",
        "urscript",
        "csv",
    ]
    assert program_format("x.txt", "RAPID") == "rapid"
    with pytest.raises(cc.CalibrationError, match="from its extension"):
        program_format("x.txt")
    path = tmp_path / "cal.toml"
    path.write_bytes(b"name = 'x'\n")
    # sha256 of the bytes above, from `printf "name = 'x'\n" | sha256sum`
    assert calibration_header(path, "passed") == "cal.toml (sha256 6d4b2ecad21d), audit: passed"


def test_docstring_example_runs():
    failures, tests = doctest.testmod(casecal.programs, optionflags=doctest.ELLIPSIS)
    assert tests > 0 and failures == 0
