"""Malformed inputs end in exit code 2, one line on stderr and no output file.

The table below holds malformed measurement CSVs, robot TOML files, deviation files and
command lines. Every one must give exit code 2, exactly one line ``casecal: error: ...`` on
stderr, no traceback, and leave no file behind (not the requested output, not a temporary
file). Each case is a small edit of a valid baseline, and `test_valid_baselines_succeed`
shows the baselines themselves pass, so each failure comes from its edit.

The property tests feed random CSV text to ``casecal identify`` and require exit code 0 or 2
and never an uncaught exception; exit code 0 only when the CSV is valid.
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
import subprocess
import sys
import tempfile
import traceback
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from casecal.cli import main

# ---------------------------------------------------------------------------------------------
# valid baselines, written without casecal


def _rr_rows(n: int) -> list[list[str]]:
    """`n` poses of the planar RR arm (unit links): q1_deg, q2_deg, x_mm, y_mm, z_mm."""
    rows = []
    for k in range(n):
        q1, q2 = 10.0 * k - 30.0, 25.0 * k - 40.0
        t1, t12 = math.radians(q1), math.radians(q1 + q2)
        x, y = math.cos(t1) + math.cos(t12), math.sin(t1) + math.sin(t12)
        rows.append([repr(q1), repr(q2), repr(x * 1e3), repr(y * 1e3), "0.0"])
    return rows


RR_HEADER = ["q1_deg", "q2_deg", "x_mm", "y_mm", "z_mm"]


def _csv(header, rows) -> str:
    return "\n".join(",".join(r) for r in [header, *rows]) + "\n"


def _rr_csv(n: int = 6, *, header=RR_HEADER, cell=None, add=None, drop=None) -> str:
    """The valid RR CSV, edited: `cell` = (row, column name, text) replaces one cell, `add` =
    (column name, text) appends a column, `drop` removes a column."""
    header, rows = list(header), _rr_rows(n)
    if add is not None:
        header.append(add[0])
        rows = [[*r, add[1]] for r in rows]
    if cell is not None:
        row, name, text = cell
        rows[row][header.index(name)] = text
    if drop is not None:
        k = header.index(drop)
        header.pop(k)
        rows = [r[:k] + r[k + 1 :] for r in rows]
    return _csv(header, rows)


VALID_CSV = _rr_csv()

ROBOT_TOML = """\
name = "planar"
convention = "dh"
length_unit = "m"
angle_unit = "deg"
source = ["test"]

[[joints]]
type = "R"
a = 1.0
alpha = 0.0
d = 0.0
limits = [-180.0, 180.0]

[[joints]]
type = "R"
a = 1.0
alpha = 0.0
d = 0.0
"""

DEVIATIONS_TOML = """\
length_unit = "mm"
angle_unit = "deg"
[deviations]
theta1 = 0.01
a2 = -0.2
"""


def _robot(old: str, new: str) -> str:
    assert old in ROBOT_TOML
    return ROBOT_TOML.replace(old, new, 1)


def _deviations(old: str, new: str) -> str:
    assert old in DEVIATIONS_TOML
    return DEVIATIONS_TOML.replace(old, new, 1)


# The commands, run in the test's temporary folder. Output always goes to out.toml / out.csv.
IDENTIFY = ["identify", "rr", "m.csv", "-o", "out.toml"]
IDENTIFY_FILE = ["identify", "robot.toml", "m.csv", "-o", "out.toml"]
SIMULATE = ["simulate", "rr", "--poses", "5", "-o", "out.csv"]
SIMULATE_DEV = [*SIMULATE, "--deviations", "dev.toml"]


def case(id_, argv, files=None, output="out.toml"):
    """One malformed input: files (name -> text or bytes) written first, then `argv` run."""
    if files is None:
        files = {"m.csv": VALID_CSV}
    return pytest.param(argv, files, output, id=id_)


# --- measurement CSVs: `casecal identify rr m.csv -o out.toml`
CSV_CASES = [
    case("csv-missing-x-column", IDENTIFY, {"m.csv": _rr_csv(drop="x_mm")}),
    case("csv-missing-joint-column", IDENTIFY, {"m.csv": _rr_csv(drop="q2_deg")}),
    case("csv-duplicated-column", IDENTIFY, {"m.csv": _rr_csv(add=("x_mm", "1.0"))}),
    case("csv-duplicated-column-with-spaces", IDENTIFY, {"m.csv": _rr_csv(add=(" y_mm ", "1"))}),
    case("csv-joint-in-deg-and-rad", IDENTIFY, {"m.csv": _rr_csv(add=("q1_rad", "0.1"))}),
    case("csv-x-and-x_mm", IDENTIFY, {"m.csv": _rr_csv(add=("x", "1.0"))}),
    case(
        "csv-revolute-joint-in-mm",
        IDENTIFY,
        {"m.csv": _rr_csv(header=["q1_mm", *RR_HEADER[1:]])},
    ),
    case(
        "csv-position-in-degrees",
        IDENTIFY,
        {"m.csv": _rr_csv(header=[*RR_HEADER[:2], "x_deg", *RR_HEADER[3:]])},
    ),
    case("csv-three-joints-for-rr", IDENTIFY, {"m.csv": _rr_csv(add=("q3_deg", "0"))}),
    case("csv-of-rr-for-scorbot", ["identify", "scorbot", "m.csv", "-o", "out.toml"]),
    case("csv-nan-cell", IDENTIFY, {"m.csv": _rr_csv(cell=(2, "x_mm", "nan"))}),
    case("csv-inf-cell", IDENTIFY, {"m.csv": _rr_csv(cell=(0, "q1_deg", "inf"))}),
    case("csv-minus-inf-cell", IDENTIFY, {"m.csv": _rr_csv(cell=(5, "z_mm", "-inf"))}),
    case("csv-text-cell", IDENTIFY, {"m.csv": _rr_csv(cell=(3, "q2_deg", "twelve"))}),
    case("csv-unicode-cell", IDENTIFY, {"m.csv": _rr_csv(cell=(1, "y_mm", "π"))}),
    case("csv-empty-cell", IDENTIFY, {"m.csv": _rr_csv(cell=(4, "y_mm", ""))}),
    case("csv-overflowing-number", IDENTIFY, {"m.csv": _rr_csv(cell=(1, "x_mm", "1e400"))}),
    case("csv-short-row", IDENTIFY, {"m.csv": VALID_CSV + "10,20,30\n"}),
    case("csv-one-row-too-long", IDENTIFY, {"m.csv": VALID_CSV + "10,20,30,40,50,60\n"}),
    case("csv-empty-file", IDENTIFY, {"m.csv": ""}),
    case("csv-whitespace-only", IDENTIFY, {"m.csv": "  \n\n   \n"}),
    case("csv-header-without-rows", IDENTIFY, {"m.csv": ",".join(RR_HEADER) + "\n"}),
    case("csv-unclosed-quote", IDENTIFY, {"m.csv": VALID_CSV + '1,2,"3,4,5\n'}),
    case("csv-not-utf8", IDENTIFY, {"m.csv": b"\xff\xfeq1,q2\x80\n\x81,\x82\n"}),
    case("csv-negative-sigma", IDENTIFY, {"m.csv": _rr_csv(add=("sigma_mm", "-0.01"))}),
    case("csv-nan-sigma", IDENTIFY, {"m.csv": _rr_csv(add=("sigma_mm", "nan"))}),
    case(
        "csv-sigma-and-sigma_mm",
        IDENTIFY,
        {
            "m.csv": _csv(
                [*RR_HEADER, "sigma_mm", "sigma"], [[*r, "0.01", "1e-5"] for r in _rr_rows(6)]
            )
        },
    ),
    # Every data row has one field more than the header. pandas then silently takes the
    # first field as the row index and shifts every value one column to the left
    # (q1 := q2, q2 := x, ...): the data are misread, not rejected.
    case(
        "csv-every-row-has-an-extra-field",
        IDENTIFY,
        {"m.csv": _csv(RR_HEADER, [[*r, "0"] for r in _rr_rows(6)])},
    ),
    case("csv-does-not-exist", ["identify", "rr", "nothing.csv", "-o", "out.toml"]),
    case(
        "csv-path-is-a-folder",
        ["identify", "rr", "folder", "-o", "out.toml"],
        {"folder/keep.txt": "not a csv"},
    ),
    case(
        "csv-two-poses-for-all-parameters",
        [*IDENTIFY, "--parameters", "all"],
        {"m.csv": _rr_csv(2)},
    ),
    case("csv-one-pose", IDENTIFY, {"m.csv": _rr_csv(1)}),
]

# --- robot TOML files: `casecal identify robot.toml m.csv -o out.toml` (and `show`)
ROBOT_CASES = [
    case(
        "toml-syntax-error",
        IDENTIFY_FILE,
        {"robot.toml": _robot("[[joints]]", "[[joints]"), "m.csv": VALID_CSV},
    ),
    case(
        "toml-missing-convention",
        IDENTIFY_FILE,
        {"robot.toml": _robot('convention = "dh"\n', ""), "m.csv": VALID_CSV},
    ),
    case(
        "toml-unknown-convention",
        IDENTIFY_FILE,
        {"robot.toml": _robot('"dh"', '"craig"'), "m.csv": VALID_CSV},
    ),
    case(
        "toml-joint-misses-a",
        IDENTIFY_FILE,
        {"robot.toml": _robot("a = 1.0\n", ""), "m.csv": VALID_CSV},
    ),
    case(
        "toml-no-joints",
        IDENTIFY_FILE,
        {"robot.toml": ROBOT_TOML.split("[[joints]]")[0], "m.csv": VALID_CSV},
    ),
    case(
        "toml-unknown-joint-type",
        IDENTIFY_FILE,
        {"robot.toml": _robot('type = "R"', 'type = "Q"'), "m.csv": VALID_CSV},
    ),
    case(
        "toml-text-instead-of-number",
        IDENTIFY_FILE,
        {"robot.toml": _robot("a = 1.0", 'a = "one"'), "m.csv": VALID_CSV},
    ),
    case(
        "toml-nan-length",
        IDENTIFY_FILE,
        {"robot.toml": _robot("d = 0.0", "d = nan"), "m.csv": VALID_CSV},
    ),
    case(
        "toml-limits-reversed",
        IDENTIFY_FILE,
        {"robot.toml": _robot("[-180.0, 180.0]", "[180.0, -180.0]"), "m.csv": VALID_CSV},
    ),
    case(
        "toml-unknown-key",
        IDENTIFY_FILE,
        {
            "robot.toml": _robot('name = "planar"', 'name = "planar"\nlenght_unit = "m"'),
            "m.csv": VALID_CSV,
        },
    ),
    case(
        "toml-unknown-length-unit",
        IDENTIFY_FILE,
        {"robot.toml": _robot('length_unit = "m"', 'length_unit = "inch"'), "m.csv": VALID_CSV},
    ),
    case(
        "toml-angle-unit-is-a-list",
        IDENTIFY_FILE,
        {"robot.toml": _robot('angle_unit = "deg"', 'angle_unit = ["deg"]'), "m.csv": VALID_CSV},
    ),
    case(
        "toml-length-unit-is-a-table",
        IDENTIFY_FILE,
        {"robot.toml": _robot('length_unit = "m"', "length_unit = {m = 1}"), "m.csv": VALID_CSV},
    ),
    case(
        "toml-source-is-a-number",
        IDENTIFY_FILE,
        {"robot.toml": _robot('source = ["test"]', "source = 5"), "m.csv": VALID_CSV},
    ),
    case(
        "toml-not-utf8",
        IDENTIFY_FILE,
        {"robot.toml": b'name = "\xff\xfe"\n', "m.csv": VALID_CSV},
    ),
    case("toml-does-not-exist", ["identify", "missing.toml", "m.csv", "-o", "out.toml"]),
    case("unknown-robot-name", ["identify", "nosuchrobot", "m.csv", "-o", "out.toml"]),
    case(
        "show-robot-toml-unknown-convention",
        ["show", "robot.toml"],
        {"robot.toml": _robot('"dh"', '"xyz"')},
        output=None,
    ),
    case("show-csv-as-robot", ["show", "m.csv"], output=None),
]

# --- deviation files: `casecal simulate rr --deviations dev.toml -o out.csv`
DEVIATION_CASES = [
    case(
        "deviations-unknown-parameter",
        SIMULATE_DEV,
        {"dev.toml": _deviations("a2 = -0.2", "gamma2 = -0.2")},
        output="out.csv",
    ),
    case(
        "deviations-syntax-error",
        SIMULATE_DEV,
        {"dev.toml": _deviations("[deviations]", "[deviations")},
        output="out.csv",
    ),
    case(
        "deviations-text-value",
        SIMULATE_DEV,
        {"dev.toml": _deviations("= 0.01", '= "small"')},
        output="out.csv",
    ),
    case(
        "deviations-nan-value",
        SIMULATE_DEV,
        {"dev.toml": _deviations("= 0.01", "= nan")},
        output="out.csv",
    ),
    case(
        "deviations-unknown-length-unit",
        SIMULATE_DEV,
        {"dev.toml": _deviations('"mm"', '"inch"')},
        output="out.csv",
    ),
    case(
        "deviations-angle-unit-is-a-list",
        SIMULATE_DEV,
        {"dev.toml": _deviations('angle_unit = "deg"', 'angle_unit = ["deg"]')},
        output="out.csv",
    ),
    case(
        "deviations-empty",
        SIMULATE_DEV,
        {"dev.toml": 'length_unit = "mm"\n'},
        output="out.csv",
    ),
    case("deviations-does-not-exist", SIMULATE_DEV, {}, output="out.csv"),
    case(
        "truth-unknown-parameter",
        [*IDENTIFY, "--truth", "dev.toml"],
        {"m.csv": VALID_CSV, "dev.toml": _deviations("a2", "zeta9")},
    ),
]

# --- options and output paths
OPTION_CASES = [
    case("identify-parameters-gamma", [*IDENTIFY, "--parameters", "gamma*"]),
    case("identify-parameters-empty", [*IDENTIFY, "--parameters", ""]),
    case("identify-parameters-unknown-name", [*IDENTIFY, "--parameters", "theta1,a9"]),
    case("identify-noise-loud", [*IDENTIFY, "--noise", "loud"]),
    case("identify-noise-negative", [*IDENTIFY, "--noise=-1mm"]),
    case("identify-noise-nan", [*IDENTIFY, "--noise", "nan"]),
    case("identify-holdout-above-1", [*IDENTIFY, "--holdout", "1.5"]),
    case("identify-holdout-negative-seed", [*IDENTIFY, "--holdout", "0.5", "--seed", "-1"]),
    case("identify-loss-scale-negative", [*IDENTIFY, "--loss", "huber", "--loss-scale=-1"]),
    case("identify-orientation-sigma-loud", [*IDENTIFY, "--orientation-sigma", "loud"]),
    case(
        "identify-deviations-out-inside-a-file",
        ["identify", "rr", "m.csv", "--deviations-out", "m.csv/dev.json"],
        output="m.csv/dev.json",
    ),
    case("identify-max-iterations-0", [*IDENTIFY, "--method", "lm", "--max-iterations", "0"]),
    case(
        "identify-output-inside-a-file",
        ["identify", "rr", "m.csv", "-o", "m.csv/out.toml"],
        output="m.csv/out.toml",
    ),
    case(
        "identify-output-is-a-folder",
        ["identify", "rr", "m.csv", "-o", "folder"],
        {"m.csv": VALID_CSV, "folder/keep.txt": "keep"},
        output=None,
    ),
    case("identify-output-empty-name", ["identify", "rr", "m.csv", "-o", ""], output=None),
    case("simulate-unknown-robot", ["simulate", "nosuchrobot", "-o", "out.csv"], {}, "out.csv"),
    case("simulate-poses-0", [*SIMULATE, "--poses", "0"], {}, "out.csv"),
    case("simulate-poses-negative", [*SIMULATE, "--poses", "-5"], {}, "out.csv"),
    # 10**15 poses: 8 PB of joint values, more than any address space; a user error
    case("simulate-poses-absurd", [*SIMULATE, "--poses", str(10**15)], {}, "out.csv"),
    case("simulate-noise-loud", [*SIMULATE, "--noise", "loud"], {}, "out.csv"),
    case("simulate-noise-infinite", [*SIMULATE, "--noise", "1e400mm"], {}, "out.csv"),
    case(
        "simulate-negative-seed",
        [*SIMULATE, "--schedule", "uniform", "--seed", "-1"],
        {},
        "out.csv",
    ),
    case(
        "simulate-output-inside-a-file",
        ["simulate", "rr", "--poses", "5", "-o", "somefile/x.csv"],
        {"somefile": "I am a file"},
        "somefile/x.csv",
    ),
    case(
        "simulate-output-is-a-folder",
        ["simulate", "rr", "--poses", "5", "-o", "folder"],
        {"folder/keep.txt": "keep"},
        None,
    ),
    case("simulate-output-empty-name", ["simulate", "rr", "--poses", "5", "-o", ""], {}, None),
    case("observability-poses-0", ["observability", "rr", "--poses", "0"], {}, None),
    case(
        "observability-parameters-gamma",
        ["observability", "rr", "--parameters", "gamma*"],
        {},
        None,
    ),
    case("observability-unknown-robot", ["observability", "nosuchrobot"], {}, None),
    case("show-unknown-robot", ["show", "nosuchrobot"], {}, None),
]

# --- command lines argparse rejects (it exits 2 by itself)
USAGE_CASES = [
    case("usage-bad-method", [*IDENTIFY, "--method", "magic"]),
    case("usage-poses-not-an-integer", [*SIMULATE, "--poses", "many"], {}, "out.csv"),
    case("usage-bad-schedule", [*SIMULATE, "--schedule", "random"], {}, "out.csv"),
    case("usage-simulate-without-output", ["simulate", "rr"], {}, None),
    case("usage-identify-without-csv", ["identify", "rr", "-o", "out.toml"]),
    case("usage-unknown-command", ["calibrate", "rr"], {}, None),
]

CASES = CSV_CASES + ROBOT_CASES + DEVIATION_CASES + OPTION_CASES


# ---------------------------------------------------------------------------------------------
# helpers


def _write(folder: Path, files: dict) -> None:
    for name, content in files.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content, encoding="utf-8")


def _tree(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def _call(argv) -> tuple[int, str, str]:
    """Run ``casecal.cli.main(argv)``: (exit code, stdout, stderr). An exception escaping
    main fails the test with its traceback (only argparse's SystemExit is an exit code)."""
    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(list(argv))
            except SystemExit as exc:
                code = exc.code
    except BaseException:
        pytest.fail(
            f"casecal {argv} raised instead of exiting 2:\n{traceback.format_exc()}",
            pytrace=False,
        )
    return code, out.getvalue(), err.getvalue()


def _assert_user_error(argv, code, err) -> None:
    where = f"casecal {' '.join(map(repr, argv))}"
    assert "Traceback" not in err, f"{where}: traceback on stderr:\n{err}"
    # warnings (e.g. joints outside their limits) come one per line before the error
    lines = err.splitlines(keepends=True)
    assert all(line.startswith("casecal: warning:") for line in lines[:-1]), err
    err = lines[-1] if lines else err
    assert code == 2, f"{where}: exit code {code}, stderr:\n{err}"
    assert err.startswith("casecal: error:"), (
        f"{where}: stderr is not 'casecal: error: ...':\n{err}"
    )
    assert err.endswith("\n") and err.count("\n") == 1, f"{where}: stderr is not one line:\n{err}"


def _assert_nothing_written(tmp_path, before, output) -> None:
    if output is not None:
        assert not (tmp_path / output).exists(), f"{output} was written"
    assert _tree(tmp_path) == before, "files appeared or vanished"


# ---------------------------------------------------------------------------------------------
# the table


def test_at_least_20_malformed_inputs():
    assert len(CASES) + len(USAGE_CASES) >= 20
    ids = [p.id for p in CASES + USAGE_CASES]
    assert len(ids) == len(set(ids))


@pytest.mark.parametrize(
    ("argv", "files", "output"),
    [
        case("identify", IDENTIFY),
        case("identify-robot-file", IDENTIFY_FILE, {"robot.toml": ROBOT_TOML, "m.csv": VALID_CSV}),
        case(
            "identify-truth",
            [*IDENTIFY, "--truth", "dev.toml"],
            {"m.csv": VALID_CSV, "dev.toml": DEVIATIONS_TOML},
        ),
        case("simulate-deviations", SIMULATE_DEV, {"dev.toml": DEVIATIONS_TOML}, "out.csv"),
    ],
)
def test_valid_baselines_succeed(tmp_path, monkeypatch, argv, files, output):
    """The inputs the malformed cases are edited from are valid."""
    monkeypatch.chdir(tmp_path)
    _write(tmp_path, files)
    code, _, err = _call(argv)
    assert code == 0, err
    assert err == ""
    assert (tmp_path / output).is_file()


@pytest.mark.parametrize(("argv", "files", "output"), CASES)
def test_malformed_input_exits_2_with_one_line(tmp_path, monkeypatch, argv, files, output):
    monkeypatch.chdir(tmp_path)
    _write(tmp_path, files)
    before = _tree(tmp_path)
    code, _, err = _call(argv)
    _assert_user_error(argv, code, err)
    _assert_nothing_written(tmp_path, before, output)


@pytest.mark.parametrize(("argv", "files", "output"), USAGE_CASES)
def test_usage_error_exits_2_with_one_line(tmp_path, monkeypatch, argv, files, output):
    """Command lines argparse rejects: the same contract (exit 2, one line, no file)."""
    monkeypatch.chdir(tmp_path)
    _write(tmp_path, files)
    before = _tree(tmp_path)
    code, _, err = _call(argv)
    _assert_user_error(argv, code, err)
    _assert_nothing_written(tmp_path, before, output)


_BY_ID = {p.id: p.values for p in CASES + USAGE_CASES}


@pytest.mark.parametrize(
    "case_id",
    [
        "csv-nan-cell",
        "csv-header-without-rows",
        "toml-unknown-convention",
        "deviations-unknown-parameter",
        "simulate-noise-loud",
        "simulate-output-inside-a-file",
    ],
)
def test_malformed_input_from_the_shell(tmp_path, case_id):
    """The same contract at the process level: ``python -m casecal.cli``."""
    argv, files, output = _BY_ID[case_id]
    _write(tmp_path, files)
    before = _tree(tmp_path)
    run = subprocess.run(
        [sys.executable, "-m", "casecal.cli", *argv],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONWARNINGS": "ignore"},
        timeout=300,
    )
    _assert_user_error(argv, run.returncode, run.stderr)
    _assert_nothing_written(tmp_path, before, output)


# ---------------------------------------------------------------------------------------------
# property tests: random CSV text never gives a traceback

COLUMNS = [
    # plausible
    *["q1", "q2", "q3", "q4", "q5", "q1_deg", "q2_deg", "q1_rad", "q2_rad", "q5_deg"],
    *["q3_mm", "q3_m", "x", "y", "z", "x_mm", "y_mm", "z_mm", "x_m", "y_um"],
    *["sigma", "sigma_mm", "sigma_um", "sigma_x_mm", "sigma_y_mm", "sigma_z_mm", "sigma_x"],
    *["p1_x_mm", "p1_y_mm", "p1_z_mm", "p2_x", "p3_z_um", "qw", "qx", "qy", "qz"],
    *["pose", "comment"],
    # implausible
    *["", " ", "q0", "q01", "q7", "q1_mm", "x_deg", "Q1", "X", "x.1", "q1.1", "nan", "None"],
    *["é", "☃", "1", "-", "q1 ", " x_mm", "sigma_deg", "#", "q99999999999999999999"],
    *["p0_x", "p1_w", "sigma_w"],
]

CELLS = [
    *["", " ", "0", "-0", "1", "-1", "3.5", "1e-320", "1e308", "-1e308", "1.7976931348623157e308"],
    *["nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1e400", "-1e400", "NA", "#N/A", "NULL"],
    *["None", "true", "0x10", "1_000", "1,5", "١٢", "１２", "abc", "—", "µ", "☃", "\x00", "  3 "],
    *['"1"', '"1,2"', '"', "'", "#", "\t1"],
]

_cell = st.one_of(
    st.sampled_from(CELLS),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.floats(min_value=-1e3, max_value=1e3).map(repr),
    st.integers(min_value=-(10**30), max_value=10**30).map(str),
    st.text(st.characters(blacklist_categories=("Cs",)), max_size=8),
)
_column = st.one_of(
    st.sampled_from(COLUMNS),
    st.text(st.characters(blacklist_categories=("Cs",)), max_size=6),
)


@st.composite
def random_csv(draw) -> str:
    header = draw(st.lists(_column, max_size=9))
    width = len(header)
    rows = draw(st.lists(st.lists(_cell, min_size=0, max_size=width + 2), max_size=8))
    newline = draw(st.sampled_from(["\n", "\r\n"]))
    lines = [",".join(header), *(",".join(r) for r in rows)]
    return newline.join(lines) + draw(st.sampled_from(["", newline]))


@st.composite
def edited_valid_csv(draw) -> str:
    """The valid RR CSV in random units, with 0 to 3 random edits."""
    n = draw(st.integers(min_value=0, max_value=8))
    deg = draw(st.booleans())
    mm = draw(st.booleans())
    header = [f"q{i}{'_deg' if deg else ''}" for i in (1, 2)]
    header += [f"{a}{'_mm' if mm else ''}" for a in "xyz"]
    rows = []
    for r in _rr_rows(n):
        q = [float(v) if deg else math.radians(float(v)) for v in r[:2]]
        p = [float(v) if mm else float(v) * 1e-3 for v in r[2:]]
        rows.append([repr(v) for v in q + p])
    for _ in range(draw(st.integers(min_value=0, max_value=3))):
        kind = draw(st.sampled_from(["cell", "rename", "add", "drop", "row", "swap"]))
        if kind == "cell" and rows:
            i = draw(st.integers(0, len(rows) - 1))
            j = draw(st.integers(0, len(rows[i]) - 1)) if rows[i] else 0
            if rows[i]:
                rows[i][j] = draw(_cell)
        elif kind == "rename" and header:
            header[draw(st.integers(0, len(header) - 1))] = draw(_column)
        elif kind == "add":
            header.append(draw(_column))
            value = draw(_cell)
            rows = [[*r, value] for r in rows]
        elif kind == "drop" and header:
            k = draw(st.integers(0, len(header) - 1))
            header.pop(k)
            rows = [r[:k] + r[k + 1 :] for r in rows]
        elif kind == "row":
            rows.append(draw(st.lists(_cell, max_size=len(header) + 2)))
        elif kind == "swap" and len(header) > 1:
            i, j = draw(st.lists(st.integers(0, len(header) - 1), min_size=2, max_size=2))
            header[i], header[j] = header[j], header[i]
    return _csv(header, rows)


JOINTS = {"rr": 2, "scorbot": 5}


def _surely_invalid(text: str, robot: str) -> str | None:
    """Why the CSV cannot be valid for `robot` (all revolute), or None when it may be.

    Conservative: when in doubt (quotes, numbered points p1_x, orientation columns) it
    says nothing. A valid file has a header, one column per joint and per coordinate,
    no data row longer than the header, and a finite number in every such cell.
    """
    if '"' in text:
        return None
    reader = csv.reader(io.StringIO(text, newline=""), skipinitialspace=True)
    try:
        lines = [r for r in reader if r]
    except csv.Error:
        return None
    if not lines:
        return "empty file"
    header = [c.strip() for c in lines[0]]
    if any(c.startswith("p") and c[1:2].isdigit() for c in header) or "qw" in header:
        return None
    rows = [r for r in lines[1:] if any(c.strip() for c in r)]
    if not rows:
        return "no data rows"
    named = [c for c in header if c]
    if len(named) != len(set(named)):
        return "a repeated column name"
    if any(len(r) > len(header) for r in rows):
        return "a row longer than the header"
    needed = [(f"q{i}", ("", "_rad", "_deg")) for i in range(1, JOINTS[robot] + 1)]
    needed += [(a, ("", "_m", "_mm", "_um")) for a in "xyz"]
    for base, units in needed:
        found = [base + u for u in units if base + u in header]
        if len(found) != 1:
            return f"{len(found)} columns for {base}"
        k = header.index(found[0])
        for r in rows:
            cell = r[k].strip() if k < len(r) else ""
            try:
                value = float(cell)
            except ValueError:
                return f"{cell!r} in column {found[0]}"
            if not math.isfinite(value):
                return f"{cell!r} in column {found[0]}"
    return None


def _check_random_csv(text: str, robot: str) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "m.csv"
        path.write_text(text, encoding="utf-8")
        out = Path(folder) / "out.toml"
        argv = ["identify", robot, str(path), "-o", str(out)]
        code, _, err = _call(argv)
        assert code in (0, 2), f"exit code {code} for CSV {text!r}:\n{err}"
        if code == 2:
            _assert_user_error(argv, code, err)
            assert sorted(os.listdir(folder)) == ["m.csv"], "a file was left behind"
        else:
            why = _surely_invalid(text, robot)
            assert why is None, f"exit 0 for an invalid CSV ({why}): {text!r}"
            assert out.is_file()


PROPERTY_SETTINGS = settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


@PROPERTY_SETTINGS
@given(text=random_csv(), robot=st.sampled_from(sorted(JOINTS)))
def test_random_csv_never_gives_a_traceback(text, robot):
    _check_random_csv(text, robot)


@PROPERTY_SETTINGS
@given(text=edited_valid_csv())
def test_edited_valid_csv_never_gives_a_traceback(text):
    _check_random_csv(text, "rr")


@PROPERTY_SETTINGS
@given(data=st.binary(max_size=200))
def test_random_bytes_never_give_a_traceback(data):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "m.csv"
        path.write_bytes(data)
        argv = ["identify", "rr", str(path), "-o", str(Path(folder) / "out.toml")]
        code, _, err = _call(argv)
        assert code in (0, 2), f"exit code {code} for bytes {data!r}:\n{err}"
        if code == 2:
            _assert_user_error(argv, code, err)
            assert sorted(os.listdir(folder)) == ["m.csv"]
