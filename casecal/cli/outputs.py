"""What a command will write, checked before it works: each output file's folder, that
it is none of the inputs nor another output's file, and that it is casecal's to replace
(`casecal.ownership`).

A leaf of the command-line package: it imports no other module of `casecal.cli`.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from ..errors import CalibrationError
from ..model.names import is_path
from ..textio import check_target, written_into


def check_output_folder(path) -> None:
    """Refuse an output folder `path` that cannot be had: a file, one whose parent does
    not exist either (one new folder is made when the file is written, none here), one
    not writable."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise CalibrationError(f"{str(p)!r} is a file, not a folder; choose another output")
    if not p.exists() and not p.absolute().parent.is_dir():
        # one new folder is what was asked for; more is a mistyped path
        raise CalibrationError(
            f"cannot create output folder {str(p)!r}: {str(p.absolute().parent)!r} does not "
            "exist either (check the path, or create the folders first)"
        )
    where = p if p.exists() else p.absolute().parent
    if not os.access(where, os.W_OK):
        raise CalibrationError(f"output folder {str(where)!r} is not writable; choose another")


OUTPUTS = {
    "output": "-o",
    "out": "OUT",
    "deviations_out": "--deviations-out",
    "camera_out": "--camera-out",
    "json": "--json",
    "residuals": "--residuals",
    "plot": "--plot",
}
"""The options that name files a command writes (``report -o`` names a folder)."""


def check_outputs(args: argparse.Namespace) -> None:
    """Refuse, before any work, an output file that could not be written or must not be
    replaced: an empty name, one in a folder that cannot be made, one of the command's
    input files (the user's measurements or targets), another output's file (one would
    silently replace the other), or an existing file casecal did not write (unless
    ``--overwrite``; `casecal.ownership`), and what `casecal.textio.check_target`
    refuses (a folder, a name ending in ``/``, a link that loops, a read-only file).
    ``-``, ``/dev/stdout``, a FIFO or another character device is written into and needs
    none of the rest."""
    outputs = [(flag, getattr(args, dest, None)) for dest, flag in OUTPUTS.items()]
    outputs = [(flag, str(path)) for flag, path in outputs if path is not None]
    if getattr(args, "command", None) == "report":
        outputs = []  # a folder, with its own rules (`casecal.report.folder`)
    seen: dict[str, str] = {}
    for flag, path in outputs:
        if not path.strip():
            raise CalibrationError(f"the {flag} file name is empty; give a file name")
        if written_into(check_target(path)):  # refuses a folder, a loop, read-only …
            continue
        check_output_folder(os.path.dirname(os.path.abspath(path)))
        key = os.path.realpath(path)
        if key in seen:
            raise CalibrationError(
                f"{seen[key]} and {flag} both name {path!r}: one file would replace the "
                "other; give each its own name"
            )
        seen[key] = flag
        for dest, value in vars(args).items():
            if dest in OUTPUTS or dest == "func" or not isinstance(value, str):
                continue
            if dest in ROBOTS and not is_path(value):
                continue  # a catalog name, read from the catalog whatever file has its name
            if value != "-" and _same_file(path, value):
                raise CalibrationError(
                    f"{flag} {path!r} is also the file read as {dest.replace('_', ' ')}: "
                    "writing it would replace that input; give the output another name"
                )
        if not getattr(args, "overwrite", False):
            _check_ours(flag, path)


ROBOTS = ("robot", "nominal")
"""Options that name a robot: a catalog robot unless `casecal.model.names.is_path`."""

OVERWRITE_HELP = (
    "replace output files that exist although casecal did not write them (without it, "
    "casecal replaces only its own unchanged outputs and refuses any other file)"
)


def _check_ours(flag: str, path: str) -> None:
    """Refuse an existing regular file that casecal did not write (or that was changed
    since it did)."""
    from ..ownership import wrote

    if os.path.isfile(path) and not wrote(path):
        raise CalibrationError(
            f"{flag} {path!r} exists and casecal did not write it (or it was changed "
            "since): casecal replaces only its own files; give another name, move the "
            "file away, or add --overwrite to replace it"
        )


def _same_file(a: str, b: str) -> bool:
    try:
        return os.path.isfile(b) and os.path.samefile(a, b)
    except OSError:  # `a` does not exist yet: a new file is no input
        return False
