"""Messages that lead with the cause and say what to do (issue 20, "messages that do not
help", from an adversarial retest).

A CSV row with a field too many gave pandas' "Error tokenizing data. C error: Expected 10
fields in line 7, saw 11"; one with a field too few was filled with an empty field (a value
missing in the middle shifted the rest into the wrong columns); a blank line was skipped,
shifting every row number a message gave. A kernel cache that is a file, or under one, or
read-only gave "File exists" or "Operation not permitted" without the folder or the fix.
``--tip-link nope`` said "link 'nope' is not below 'base_link'".
"""

from __future__ import annotations

import errno
import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path

import casadi as ca
import pytest

import casecal as cc
from casecal.cli import main
from casecal.data import table
from casecal.errors import CalibrationError
from casecal.model import _native
from casecal.model.urdf import read_urdf

KR16 = str(Path(__file__).parent.parent / "examples" / "kr16_2.urdf")


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """30 simulated poses of the puma560 (9 columns): the file's lines."""
    path = tmp_path_factory.mktemp("sim") / "sim.csv"
    argv = ["simulate", "puma560", "--poses", "30", "--schedule", "uniform"]
    assert main([*argv, "-o", str(path)]) == 0
    return path.read_text().splitlines()


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("casecal: error: "), err
    return err


def identify(lines, tmp_path, capsys, name="bad.csv") -> str:
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    assert main(["identify", "puma560", str(path)]) == 2
    return one_error_line(capsys)


def with_field(lines, line, value="7"):
    """`lines` with one field more at the end of file line `line` (the header is line 1)."""
    lines = list(lines)
    lines[line - 1] += "," + value
    return lines


@pytest.mark.parametrize("line", [2, 7, 31])
def test_a_row_with_a_field_too_many_is_named_by_its_line(simulated, tmp_path, capsys, line):
    """Line 2 once gave 'some rows have more fields than the header' (no line); the others
    pandas' 'Error tokenizing data. C error: Expected 9 fields in line 7, saw 10'."""
    err = identify(with_field(simulated, line), tmp_path, capsys)
    assert f"line {line} has 10 fields, the header 9: check the delimiters" in err, err
    assert "1,5 for 1.5" in err and "column name" in err and "C error" not in err, err


def test_a_decimal_comma_is_suggested(simulated, tmp_path, capsys):
    lines = list(simulated)
    lines[11] = lines[11].replace(".", ",", 1)  # file line 12, its first value
    err = identify(lines, tmp_path, capsys)
    assert "line 12 has 10 fields, the header 9" in err and "1,5 for 1.5" in err, err


@pytest.mark.parametrize("chunk", [7, 20_000])
def test_the_parsers_line_is_the_files_line(simulated, tmp_path, capsys, monkeypatch, chunk):
    """Where the parser, not the row check, refuses the row (its count of lines includes
    the header and blank lines, and goes on across chunks): the same line."""
    monkeypatch.setattr(table, "_check_rows", lambda *args: None)
    monkeypatch.setattr(table, "CHUNK_ROWS", chunk)  # 7: the bad row in the 5th chunk
    lines = with_field(simulated, 31)
    lines.insert(4, "")  # a blank line 5: the bad row moves to line 32
    err = identify(lines, tmp_path, capsys)
    assert "line 32 has 10 fields, the header 9: check the delimiters" in err, err


def test_a_long_row_in_a_later_chunk_is_named(simulated, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(table, "CHUNK_ROWS", 7)
    monkeypatch.setattr(table, "WINDOW", 300)  # the row check too, a few lines at a time
    err = identify(with_field(simulated, 29), tmp_path, capsys)
    assert "line 29 has 10 fields, the header 9" in err, err


@pytest.mark.parametrize("drop", [2, 8])
def test_a_short_row_is_named_as_short(simulated, tmp_path, capsys, drop):
    """Dropping the last field gave "row 7, column 'z_mm': '' is not a finite number";
    dropping one in the middle shifted the rest one column left, into the wrong joints
    (here a last column casecal does not read took the place of z_mm)."""
    lines = [simulated[0] + ",temp_C"] + [x + ",21.5" for x in simulated[1:]]
    fields = lines[6].split(",")
    del fields[drop]
    lines[6] = ",".join(fields)
    err = identify(lines, tmp_path, capsys)
    assert "line 7 has 9 fields, the header 10: the row is short" in err, err
    assert "one value per column" in err, err


def test_a_short_last_row_without_newline(simulated, tmp_path, capsys):
    lines = list(simulated)
    lines[-1] = lines[-1].rsplit(",", 1)[0]
    path = tmp_path / "short.csv"
    path.write_text("\n".join(lines))
    assert main(["identify", "puma560", str(path)]) == 2
    err = one_error_line(capsys)
    assert f"line {len(lines)} has 8 fields, the header 9: the row is short" in err, err


@pytest.mark.parametrize("where", [1, 5, 30])
@pytest.mark.parametrize("blank", ["", "   ", "\r"])
def test_a_blank_line_between_rows_is_refused(simulated, tmp_path, capsys, where, blank):
    """A skipped blank line shifted every row number below it: 'row 20' named line 21."""
    lines = list(simulated)
    lines.insert(where - 1, blank)
    err = identify(lines, tmp_path, capsys)
    assert f"line {where} is blank; delete the blank lines (e.g. grep -v" in err, err


def test_a_blank_line_before_a_later_window_is_refused(simulated, tmp_path, monkeypatch):
    monkeypatch.setattr(table, "WINDOW", 300)
    lines = list(simulated)
    lines[9:9] = ["", "", ""]
    path = tmp_path / "blank.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(CalibrationError, match="line 10 is blank"):
        cc.read_csv(path, cc.load_robot("puma560"))


def test_blank_lines_at_the_end_are_read(simulated, tmp_path):
    path = tmp_path / "end.csv"
    path.write_text("\r\n".join(simulated) + "\r\n\r\n  \n\n")
    assert cc.read_csv(path, cc.load_robot("puma560")).n_poses == 30


def test_quoted_fields_are_counted_as_the_parser_does(simulated, tmp_path, capsys):
    """A quoted note may hold commas: the count is of fields, not of commas."""
    lines = [simulated[0] + ",note"] + [x + ',"left, then right"' for x in simulated[1:]]
    path = tmp_path / "quoted.csv"
    path.write_text("\n".join(lines) + "\n")
    assert cc.read_csv(path, cc.load_robot("puma560")).n_poses == 30
    lines[12] = lines[12].replace(',"left', ',7,"left')
    err = identify(lines, tmp_path, capsys)
    assert "line 13 has 11 fields, the header 10" in err, err
    lines[12] = ",".join(simulated[12].split(",")[:8])
    err = identify(lines, tmp_path, capsys)
    assert "line 13 has 8 fields, the header 10: the row is short" in err, err


@pytest.mark.parametrize("sep", [";", "\t"])
def test_other_separators_are_counted(simulated, tmp_path, capsys, sep):
    lines = [x.replace(",", sep) for x in simulated]
    lines[6] = lines[6].rsplit(sep, 1)[0]
    err = identify(lines, tmp_path, capsys)
    name = {";": "semicolon", "\t": "tab"}[sep]
    assert f"line 7 has 8 fields, the header 9: the row is short (a value or a {name}" in err


# --- the kernel cache -------------------------------------------------------------------

needs_cc = pytest.mark.skipif(
    shutil.which("cc") is None and shutil.which("gcc") is None, reason="no C compiler"
)

PROBE = """
import casecal as cc
from casecal.model import _evaluate  # no budget: auto compiles at the first batch (issue 23)
_evaluate.COMPILE_SECONDS_BASE = _evaluate.COMPILE_SECONDS_PER_INSTRUCTION = 0.0
r = cc.load_robot("puma560")
q = cc.poses.uniform(r, 400, seed=0)
r.position(q), r.position_jacobian(q, ["theta*"])
print("evaluated")
"""


def a_file(tmp_path):
    (tmp_path / "a-file").write_text("mine")
    return tmp_path / "a-file", "is a file, not a folder"


def under_a_file(tmp_path):
    (tmp_path / "a-file").write_text("mine")
    return tmp_path / "a-file" / "cache", f"cannot be made: {tmp_path / 'a-file'} is a file"


@needs_cc
@pytest.mark.parametrize("where", [a_file, under_a_file])
def test_a_cache_that_is_a_file_names_the_folder(tmp_path, where):
    """It gave 'could not compile kernels ([Errno 17] File exists: ...)'."""
    cache, why = where(tmp_path)
    env = {**os.environ, "CASECAL_CACHE": str(cache), "CASECAL_BACKEND": "auto"}
    run = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True)
    assert run.returncode == 0 and run.stdout == "evaluated\n", run.stderr
    assert len(run.stderr.splitlines()) == 1, run.stderr  # two kernels, one line
    assert f"kernel cache {cache} {why}; set CASECAL_CACHE to a writable folder" in run.stderr
    assert "evaluating with numpy" in run.stderr and "Errno" not in run.stderr, run.stderr
    assert (tmp_path / "a-file").read_text() == "mine"


def small_function():
    x, p = ca.SX.sym("x", 2), ca.SX.sym("p", 1)
    return ca.Function("casecal_test_scale", [x, p], [x * p])


@needs_cc
@pytest.mark.parametrize(
    ("code", "named"),
    [(errno.EACCES, True), (errno.EROFS, True), (errno.EPERM, False), (errno.EROFS, False)],
)
@pytest.mark.parametrize("exists", [True, False])
def test_a_read_only_cache_names_the_folder(tmp_path, monkeypatch, caplog, code, named, exists):
    """It gave 'could not compile kernels ([Errno 1] Operation not permitted)'. Writing
    into the cache (making it, a build folder in it, renaming into it) fails as on a
    read-only disk or a folder of someone else's; elsewhere (the system's temporary folder,
    where CasADi writes its C) all works."""
    cache = tmp_path / "cache"
    if exists:
        cache.mkdir()
    real_mkdir, real_replace = os.mkdir, os.replace

    def refuse(path):
        if str(path).startswith(str(cache)):
            raise OSError(code, os.strerror(code), *([str(path)] if named else []))

    def mkdir(path, *args, **kwargs):
        refuse(path)
        return real_mkdir(path, *args, **kwargs)

    def replace(src, dst, *args, **kwargs):
        refuse(dst)
        return real_replace(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "mkdir", mkdir)
    monkeypatch.setattr(os, "replace", replace)
    monkeypatch.setenv("CASECAL_CACHE", str(cache))
    monkeypatch.setattr(_native, "_SAID", set())
    with caplog.at_level(logging.INFO, logger=_native.__name__):
        for key in ("first", "second"):  # every kernel fails alike: one line
            assert _native.kernel(("test", key), small_function, 2, 1, 2) is None
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1, said
    why = "is not writable" if exists else "cannot be made"
    assert said[0].startswith(f"kernel cache {cache} {why} ({os.strerror(code)}); "), said
    assert "set CASECAL_CACHE to a writable folder; evaluating with numpy" in said[0], said
    assert not exists or list(cache.iterdir()) == []


# --- the ends of a URDF chain -----------------------------------------------------------

KR16_LINKS = "base_link, link1, link2, link3, link4, link5, link6, tool0"


@pytest.mark.parametrize("flag", ["--tip-link", "--base-link"])
def test_an_unknown_link_lists_the_links(capsys, flag):
    """--tip-link nope said "link 'nope' is not below 'base_link'"; --base-link nope did
    not say how to give another."""
    assert main(["show", KR16, flag, "nope"]) == 2
    err = one_error_line(capsys)
    assert f"{KR16}: no link 'nope' in the file; its links: {KR16_LINKS}" in err, err
    assert f"give one of them with {flag}" in err, err


def test_a_link_that_is_not_below_the_base_keeps_its_message(capsys):
    assert main(["show", KR16, "--base-link", "link3", "--tip-link", "link1"]) == 2
    err = one_error_line(capsys)
    assert "link 'link1' is not below 'link3'" in err, err


def test_a_declared_link_without_joints_is_not_below(tmp_path):
    """A link the file declares but no joint reaches is there: it is not below the base."""
    text = Path(KR16).read_text().replace("</robot>", '<link name="spare"/></robot>')
    with pytest.raises(CalibrationError, match="link 'spare' is not below 'base_link'"):
        read_urdf(text, "kr16", tip_link="spare")


def test_a_long_list_of_links_is_cut(tmp_path):
    links = "".join(f'<link name="l{i}"/>' for i in range(40))
    joints = "".join(
        f'<joint name="j{i}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
        '<axis xyz="0 0 1"/><limit lower="-1" upper="1"/></joint>'
        for i in range(39)
    )
    text = f'<robot name="long">{links}{joints}</robot>'
    with pytest.raises(CalibrationError) as info:
        read_urdf(text, "long.urdf", tip_link="nope")
    message = str(info.value)
    assert "its links: l0, l1, l2" in message and "(40 links)" in message, message
    assert "l39" not in message and "--tip-link" in message, message
