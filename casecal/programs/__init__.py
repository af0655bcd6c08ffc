"""Program compensation: a robot program with its literal joint targets compensated, and
every other character as it was.

The robot runs programs, not arrays: `compensate_program` finds the joint targets of a
KUKA KRL, ABB RAPID, URScript or CSV file (one module per format: `krl`, `rapid`,
`urscript`, `csv_program`), compensates them all at once with `casecal.compensate`, and
writes the new values into the original text at the targets' places, in the format's own
units and number style. Targets that cannot be compensated (at or near a singularity,
outside the joint limits, not reached) keep their values and are listed with the reason;
so are targets casecal does not compensate (Cartesian ones, relative moves, positions
computed at run time). A target-like construct the parser cannot read is refused with
its line number, never passed through silently.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CalibrationError
from . import csv_program, krl, rapid, urscript
from ._text import fixed

FORMATS = {"krl": krl, "rapid": rapid, "urscript": urscript, "csv": csv_program}
EXTENSIONS = {
    ".src": "krl",
    ".dat": "krl",
    ".mod": "rapid",
    ".modx": "rapid",
    ".prg": "rapid",
    ".script": "urscript",
    ".urscript": "urscript",
    ".csv": "csv",
}
MARK = "compensated by casecal"
"""The header comment starts with this; a program that carries it is refused (compensating
twice would apply the calibration twice)."""


@dataclass(frozen=True)
class ProgramResult:
    """A compensated program.

    Attributes
    ----------
    text : str
        The program: the input with new joint values (and the header comment, except for
        CSV); every other character as it was, line endings included.
    changed : tuple of int
        Lines (1-based, of the input) whose target was compensated.
    skipped : tuple of (int, str)
        Lines (of the input) left as they were, and why: targets the compensation could not
        correct (`casecal.model.compensate.Compensation.reason`) and targets that are not
        literal joint targets (Cartesian, relative, computed at run time).
    header : str
        The header line without its comment mark ("" when none was given).
    compensation : Compensation or None
        `casecal.compensate`'s answer for the targets, in their order in the text (None
        when the program has none).
    """

    text: str
    changed: tuple[int, ...]
    skipped: tuple[tuple[int, str], ...]
    header: str = ""
    compensation: object | None = None


def program_format(path, fmt: str | None = None) -> str:
    """The format of a program file: `fmt` if given, else from the extension (.src, .dat:
    "krl"; .mod, .modx, .prg: "rapid"; .script, .urscript: "urscript"; .csv: "csv")."""
    if fmt is not None:
        if fmt.lower() not in FORMATS:
            raise CalibrationError(
                f"unknown program format {fmt!r}; use one of {', '.join(FORMATS)}"
            )
        return fmt.lower()
    suffix = Path(str(path)).suffix.lower()
    if suffix not in EXTENSIONS:
        raise CalibrationError(
            f"cannot tell the program format of {str(path)!r} from its extension; name it "
            f"({', '.join(FORMATS)})"
        )
    return EXTENSIONS[suffix]


def calibration_header(calibration_file, verdict: str) -> str:
    """The `compensate_program` header naming the calibration: its file name, the first 12
    hex digits of the file's SHA-256 and the audit's verdict (e.g. ``Calibration.message``).

    >>> calibration_header("calibrated.toml", "passed")  # doctest: +SKIP
    'calibrated.toml (sha256 3f2a9c01b7de), audit: passed'
    """
    path = Path(calibration_file)
    try:
        digest = hashlib.sha256(path.read_bytes()).hexdigest()[:12]
    except OSError as exc:
        raise CalibrationError(
            f"cannot read calibration file {str(path)!r}: {exc.strerror}"
        ) from None
    return f"{path.name} (sha256 {digest}), audit: {verdict}"


def compensate_program(
    calibrated,
    text: str,
    fmt: str,
    nominal=None,
    header: str | None = None,
    frame: str = "robot",
    orientation: bool | None = None,
) -> ProgramResult:
    """Compensate the literal joint targets of a robot program (`casecal.compensate`).

    Parameters
    ----------
    calibrated : Robot or Calibration
        The calibrated robot (a `Calibration`: its ``robot``, and its ``nominal`` unless
        `nominal` is given).
    text : str
        The program, as read (line endings kept).
    fmt : {"krl", "rapid", "urscript", "csv"}
        Its format (`program_format` tells it from a file's extension). Units at the edge:
        KRL and RAPID degrees (mm for a linear axis), written with 6 decimals (1e-6°);
        URScript radians with 8 decimals (1e-8 rad), ``d2r(...)`` degrees with 6; CSV its
        columns' units, written exactly (shortest round-trip decimal).
    nominal : Robot, optional
        The robot the controller believes (as in `casecal.compensate`).
    header : str, optional
        What the header comment says after "compensated by casecal: ", e.g.
        `calibration_header` (calibration file, its SHA-256, the audit's verdict). Written
        as a comment in the format's syntax (KRL ``;`` after the ``DEF``/``DEFDAT`` line,
        RAPID ``!`` after the ``MODULE`` line, URScript ``#`` on the first line); a CSV
        file gets none (casecal's CSV reader refuses comments): `ProgramResult.header`.
    frame, orientation
        As in `casecal.compensate`.

    Returns
    -------
    ProgramResult

    Raises
    ------
    CalibrationError
        A target-like construct that cannot be read (a value that is not a number literal,
        an unclosed or misshapen target), with its line; a program already compensated by
        casecal; the errors of `casecal.compensate`.

    Examples
    --------
    >>> import casecal as cc
    >>> nominal = cc.load_robot("ur5e")
    >>> real = nominal.with_deviations({"a2": 3e-4, "theta3": 5e-4})
    >>> program = "def p():\\n  movej([0.1, -1.2, 1.3, -1.7, -1.5, 0.2], a=1.2, v=0.25)\\nend\\n"
    >>> out = cc.compensate_program(real, program, "urscript", nominal=nominal, header="demo")
    >>> print(out.text)  # doctest: +ELLIPSIS
    # compensated by casecal: demo
    def p():
      movej([0.0999..., -1.1998..., 1.2986..., -1.6993..., -1.4999..., 0.2000...], a=1.2, v=0.25)
    end
    <BLANKLINE>
    >>> out.changed, out.skipped
    ((2,), ())
    """
    from ..model.compensate import compensate

    if fmt is None:
        raise CalibrationError(f"give the program format: one of {', '.join(FORMATS)}")
    module = FORMATS[program_format("", fmt)]
    if hasattr(calibrated, "robot") and hasattr(calibrated, "nominal"):  # a Calibration
        nominal = calibrated.nominal if nominal is None else nominal
        calibrated = calibrated.robot
    _check_not_compensated(text, module)
    found = module.find(text, calibrated)
    result = None
    edits, changed, skipped = [], [], list(found.skipped)
    if found.targets:
        q = np.array([t.q for t in found.targets])
        result = compensate(calibrated, q, nominal, frame=frame, orientation=orientation)
        render = getattr(module, "render", fixed)
        for k, target in enumerate(found.targets):
            if not result.ok[k]:
                skipped.append((target.line, result.reason[k]))
                continue
            edits += _edits(text, target, result.q[k], render)
            changed.append(target.line)
    out = _splice(text, edits)
    if header is not None and module.COMMENT is not None:
        out = _with_header(out, module, header)
    return ProgramResult(
        text=out,
        changed=tuple(sorted(set(changed))),
        skipped=tuple(sorted(skipped)),
        header="" if header is None else f"{MARK}: {header}",
        compensation=result,
    )


def _edits(text: str, target, q: np.ndarray, render) -> list[tuple[int, int, str]]:
    """(start, end, new text) for the values of `target` that change when written."""
    edits = []
    for (a, b), value, unit in zip(target.spans, q, target.units, strict=True):
        new = render(float(value), unit)
        if float(new) != float(text[a:b]):
            edits.append((a, b, new))
    return edits


def _splice(text: str, edits) -> str:
    parts, at = [], 0
    for a, b, new in sorted(edits):
        parts += [text[at:a], new]
        at = b
    return "".join([*parts, text[at:]])


def _with_header(text: str, module, header: str) -> str:
    """`text` with the header comment as a line of its own where `module` puts it."""
    if "\n" in header or "\r" in header:
        raise CalibrationError("the program header must be one line; remove its line breaks")
    bom = "\ufeff" if text.startswith("\ufeff") else ""  # stays first, before the header
    text = text[len(bom) :]
    at = module.header_at(text)
    newline = "\r\n" if "\r\n" in text else "\n"
    if at > 0 and not text[:at].endswith("\n"):
        text, at = text + newline, at + len(newline)
    indent = re.match(r"[ \t]*", text[at:]).group()
    return f"{bom}{text[:at]}{indent}{module.COMMENT} {MARK}: {header}{newline}{text[at:]}"


def _check_not_compensated(text: str, module) -> None:
    if module.COMMENT is None:
        return
    for line, raw in enumerate(text.splitlines(), start=1):
        body = raw.strip()
        if body.startswith(module.COMMENT) and MARK in body:
            raise CalibrationError(
                f"line {line}: the program was already compensated by casecal; compensate "
                "the original program (compensating twice applies the calibration twice)"
            )
