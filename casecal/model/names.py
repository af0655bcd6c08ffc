"""Robot names and robot paths: which one an argument is, and the catalog's listing.

The rule, the same on the command line and in Python: a string with no slash and no suffix
(``puma560``, ``rr``) is a catalog name and only that; a file or folder of that name in the
working folder neither replaces nor breaks the catalog robot. A string with a slash or a
suffix (``./rr``, ``arm.toml``, ``robots/arm``) is a path, as is ``-`` (standard input) and
any `pathlib.Path` (Python code that makes a Path has said which it means).
"""

from __future__ import annotations

import difflib
import os
from importlib import resources
from pathlib import Path, PurePath

from ..errors import CalibrationError

ROBOT_SUFFIXES = (".toml", ".urdf", ".xacro", ".yaml", ".yml")
"""A robot named with one of these is a path, never a catalog name."""


def catalog_dir():
    """The folder of the catalog's robot files (inside the package)."""
    return resources.files("casecal.model") / "robots"


def robots() -> list[str]:
    """Names of the robots in the catalog, sorted.

    Returns
    -------
    list of str
        Each loads with ``casecal.load_robot(name)``.
    """
    return sorted(p.name[:-5] for p in catalog_dir().iterdir() if p.name.endswith(".toml"))


def is_path(name) -> bool:
    """Whether `name` names a file (True) or a catalog robot (False); see the module doc."""
    if isinstance(name, PurePath | os.PathLike):
        return True
    text = str(name)
    return text == "-" or "/" in text or "\\" in text or bool(PurePath(text).suffix)


def path_text(path) -> str:
    """The text of `path` such that `is_path` reads it back as a path: ``./arm``, never the
    bare ``arm`` (which would be a catalog name)."""
    text = str(path)
    return text if is_path(text) else f".{os.sep}{text}"


def catalog_entry(name: str):
    """The catalog file of robot `name`; `CalibrationError` saying what to do if none."""
    entry = catalog_dir() / f"{name}.toml"
    if entry.is_file():
        return entry
    if Path(name).is_file():  # the user may have meant this file: say how to give it
        raise CalibrationError(
            f"no catalog robot {name!r}; to use the file {name!r} in this folder, give it as "
            f"./{name} (or rename it with its suffix, e.g. {name}.toml)"
        )
    known = robots()
    close = difflib.get_close_matches(name, known, n=3)
    maybe = f"did you mean {' or '.join(close)}? " if close else ""
    raise CalibrationError(
        f"unknown robot {name!r}: no catalog robot of that name; {maybe}catalog robots are: "
        f"{', '.join(known)} (a robot file is given by its path, with its suffix "
        f"({', '.join(ROBOT_SUFFIXES)}) or a slash)"
    )


def namesake_note(name) -> str | None:
    """A note when catalog name `name` is also a file in the working folder (not read)."""
    if is_path(name) or str(name) not in robots() or not Path(str(name)).is_file():
        return None
    return (
        f"{name!r} is the catalog robot; the file {name!r} in this folder is not read "
        f"(give ./{name} to use it)"
    )


def missing_file(path: Path) -> str:
    """The message for a robot file that does not exist: what the folder holds instead."""
    folder = path.parent
    where = "the current folder" if str(folder) in ("", ".") else f"folder {str(folder)!r}"
    if not folder.is_dir():
        return f"no file {str(path)!r}: {where} does not exist; check the path"
    try:
        files = sorted(p.name for p in folder.iterdir() if p.suffix.lower() in ROBOT_SUFFIXES)
    except OSError:
        files = []
    stems = {Path(f).stem.lower(): f for f in files}  # the suffix alone is no likeness
    close = [stems[c] for c in difflib.get_close_matches(path.stem.lower(), stems, n=3)]
    if close:
        found = f"; did you mean {' or '.join(close)}?"
    elif files:
        shown = ", ".join(files[:8]) + (f" … ({len(files)} in all)" if len(files) > 8 else "")
        found = f"; robot files there: {shown}"
    else:
        found = f"; {where} holds no robot file ({', '.join(ROBOT_SUFFIXES)})"
    if not path.suffix and str(path) in robots():  # load_robot(Path("rr")) is a path
        found += f"; for the catalog robot give the name as a string: load_robot({str(path)!r})"
    return f"no file {str(path)!r}: it does not exist in {where}{found}"
