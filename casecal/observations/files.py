"""Camera measurement files: one row per view, its joint values and its corners' pixels.

Columns:

- the joint columns of `casecal.read_csv` (``q1_deg`` …, ``q1_rad``, ``q1_mm``, or a
  URDF robot's joint names with a unit);
- ``c{k}_u_px`` and ``c{k}_v_px`` for every corner k = 0 … rows·cols − 1 of the board, in
  `casecal.observations.target.Checkerboard.corners` order (OpenCV's
  ``findChessboardCorners(image, (cols, rows))`` order; u along the image's rows, v down,
  origin at the centre of the top-left pixel, as OpenCV's); both cells empty where the
  detector did not find the corner;
- optionally ``sigma_px``, one value for every row: the pixel noise σ;
- optionally ``session``: each view's placement (the camera or the board placed anew),
  every placement but one with its ``[camera.sessions.LABEL]`` table in the camera file.

`read_pixels` needs the robot (for the joints) and the nominal camera (`CameraSetup`: for
the board's size and to start the fit from); `write_pixels` writes what it reads.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from ..data.files import _numbers, joint_columns, read_joints
from ..data.table import read_table
from ..errors import CalibrationError
from ..model.robot import Robot
from ..textio import write_atomic
from .pixels import PixelMeasurements
from .simulate import CameraSetup

_CORNER = re.compile(r"^c(\d+)_([uv])_px$")


def read_pixels(
    path,
    robot: Robot,
    setup: CameraSetup,
    sigma_px=None,
    fit_intrinsics: bool = True,
    sessions=None,
) -> PixelMeasurements:
    """Read a camera measurement file (module doc).

    Parameters
    ----------
    path : str or path-like
        The CSV file (``"-"``: standard input).
    robot : Robot
        The robot the joint values are of.
    setup : CameraSetup
        The nominal camera and board: the board says how many corners each row has.
    sigma_px : float, optional
        The pixel noise σ (px), when the file has no ``sigma_px`` column; given with one,
        they must agree.
    fit_intrinsics : bool
        As `PixelMeasurements`'.
    sessions : dict of str to CameraSetup, optional
        With a ``session`` column: the nominal camera of each placement but one, whose
        views are seen with `setup` (`read_cameras`).

    Raises
    ------
    CalibrationError
        For a missing or extra corner column (a board of other rows and columns), one cell
        of a corner's pair empty, no σ, or anything `casecal.read_csv` refuses in the joints.
    """
    df, label = read_table(path, "camera measurement file")
    session = _sessions(df, label, sessions or {})
    q = read_joints(df, robot, label)
    n = setup.board.n_corners
    found = {}
    for column in df.columns:
        match = _CORNER.match(str(column))
        if match:
            if match.group(1) != str(int(match.group(1))):
                raise CalibrationError(
                    f"{label}: column {column!r}: corner numbers are written without leading "
                    f"zeros (c{int(match.group(1))}_{match.group(2)}_px)"
                )
            found.setdefault(int(match.group(1)), set()).add(match.group(2))
    if not found:
        raise CalibrationError(
            f"{label}: no corner columns; give c0_u_px, c0_v_px … c{n - 1}_v_px (the "
            f"{setup.board.rows} × {setup.board.cols} board's corners, in pixels)"
        )
    beyond = sorted(k for k in found if k >= n)
    missing = [k for k in range(n) if found.get(k) != {"u", "v"}]
    if beyond or missing:
        what = f"columns up to c{max(found)}_…" if beyond else f"no c{missing[0]}_u_px/v_px pair"
        raise CalibrationError(
            f"{label}: {what}, but the board of the setup has {setup.board.rows} × "
            f"{setup.board.cols} = {n} inner corners (c0 … c{n - 1}); give the board the "
            "file's rows and columns (inner corners, as OpenCV's patternSize = (cols, rows))"
        )
    uv = np.empty((len(df), n, 2))
    for k in range(n):
        for j, axis in enumerate("uv"):
            uv[:, k, j] = _cells(df, f"c{k}_{axis}_px", label)
    sigma = _sigma(df, label, sigma_px)
    setups, extra = None, {}
    if session is not None:  # the placement seen with `setup` is the one not named
        labels = list(dict.fromkeys(session.tolist()))
        every = {name: sessions.get(name, setup) for name in labels}
        setup, setups = every[labels[0]], {name: every[name] for name in labels[1:]}
        extra = {"session": session, "setups": setups}
    try:
        return PixelMeasurements(q, uv, setup, sigma, fit_intrinsics, **extra)
    except CalibrationError as exc:  # say which file (its rows are views + 2)
        raise CalibrationError(f"{label}: {exc} (file row = view + 2)") from None


def write_pixels(path, measurements: PixelMeasurements, robot: Robot) -> None:
    """Write `measurements` as a camera measurement file (module doc), atomically: joint
    values in degrees (revolute) and millimetres (prismatic), pixels to 17 digits, empty
    cells for corners not found, and ``sigma_px``."""
    data = joint_columns(measurements.q, robot)
    if measurements.session is not None:
        data = {"session": measurements.session, **data}
    for k in range(measurements.pixels.shape[1]):
        for j, axis in enumerate("uv"):
            data[f"c{k}_{axis}_px"] = measurements.pixels[:, k, j]
    data["sigma_px"] = np.full(measurements.n_poses, measurements.sigma_px)
    text = pd.DataFrame(data).to_csv(index=False, float_format="%.17g", lineterminator="\n")
    write_atomic(path, text)


def _cells(df: pd.DataFrame, column: str, label: str) -> np.ndarray:
    """A pixel column: numbers, NaN for an empty cell; anything else refused by its row."""
    col = df[column]
    empty = col.isna().to_numpy() | (col.astype(str).str.strip() == "").to_numpy()
    text = col.astype(str).str.strip()
    values = pd.to_numeric(text.where(~empty, "nan"), errors="coerce").to_numpy(float, copy=True)
    bad = ~empty & ~np.isfinite(values)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise CalibrationError(
            f"{label}: row {row + 2}, column {column!r}: {str(col.iloc[row])!r} is not a "
            "finite number of pixels; leave both cells of a corner empty where it was not found"
        )
    values[empty] = np.nan
    return values


def _sessions(df: pd.DataFrame, label: str, sessions: dict) -> np.ndarray | None:
    """The ``session`` column's labels (N,), checked against the camera's placements:
    every label but one named in `sessions`; None without the column."""
    if "session" not in df:
        if sessions:
            raise CalibrationError(
                f"{label}: the camera file has placements ({', '.join(sessions)}) but the "
                "views have no session column saying which view is whose"
            )
        return None
    values = df["session"]
    if values.isna().any():
        row = int(np.flatnonzero(values.isna().to_numpy())[0])
        raise CalibrationError(f"{label}: row {row + 2}: empty session; give every view one")
    session = values.astype(str).str.strip().to_numpy()
    labels = list(dict.fromkeys(session.tolist()))
    unnamed = [name for name in labels if name not in sessions]
    unknown = [name for name in sessions if name not in labels]
    if len(unnamed) != 1 or unknown:
        raise CalibrationError(
            f"{label}: sessions {', '.join(labels)} in the views, placements "
            f"{', '.join(sessions) or 'none'} in the camera file: every session but the "
            "[camera] table's needs its [camera.sessions.LABEL] table, and each table its views"
        )
    return session


def _sigma(df: pd.DataFrame, label: str, sigma_px) -> float:
    """The pixel σ from the ``sigma_px`` column or the argument, refusing a disagreement."""
    if "sigma_px" not in df:
        if sigma_px is None:
            raise CalibrationError(
                f"{label}: no sigma_px column and no sigma_px given; give the pixel noise "
                "(a detector's sub-pixel corners: 0.1–0.5 px)"
            )
        return sigma_px
    values = _numbers(df, "sigma_px", label)
    if np.any(values != values[0]):
        raise CalibrationError(
            f"{label}: sigma_px differs between rows ({values.min():g} … {values.max():g} px); "
            "one pixel noise for every view is supported"
        )
    if sigma_px is not None and float(sigma_px) != values[0]:
        raise CalibrationError(
            f"{label}: sigma_px {values[0]:g} px in the file but {sigma_px!r} given; give one"
        )
    return float(values[0])


CAMERA_KEYS = {
    "mode": "eye_to_hand or eye_in_hand",
    "camera_xyz_mm": "the camera's position: in the world (eye_to_hand) or the tool frame",
    "camera_rpy_deg": "its rotation, roll pitch yaw (Rz·Ry·Rx), degrees",
    "target_xyz_mm": "the board's position: in the tool frame (eye_to_hand) or the world",
    "target_rpy_deg": "its rotation, roll pitch yaw, degrees",
    "fx": "focal length along u, px",
    "fy": "focal length along v, px",
    "cx": "principal point u, px",
    "cy": "principal point v, px",
    "distortion": "k1 k2 p1 p2 k3 (OpenCV's order; optional, default none)",
    "image_size": "width, height in px",
    "board_rows": "inner corners per column",
    "board_cols": "inner corners per row",
    "board_spacing_mm": "side of a square, mm",
}
"""The keys of a camera file's ``[camera]`` table and what each holds."""


def read_camera(path) -> CameraSetup:
    """A nominal (or fitted) camera from a TOML file's ``[camera]`` table (`CAMERA_KEYS`).

    "World" is the frame the robot's tool poses are given in (`casecal.Robot.fk`).
    """
    return read_cameras(path)[0]


def read_cameras(path) -> tuple[CameraSetup, dict]:
    """The ``[camera]`` table's camera and each ``[camera.sessions.LABEL]`` table's: a
    later placement's moved pose (``camera_xyz_mm``, ``camera_rpy_deg`` eye-to-hand;
    ``target_…`` eye-in-hand), the rest the first's.

    Returns
    -------
    setup : CameraSetup
    sessions : dict of str to CameraSetup
        Empty without session tables.
    """
    import tomllib

    from ..textio import read_text

    label = str(path)
    try:
        table = tomllib.loads(read_text(path, "camera file")).get("camera")
    except tomllib.TOMLDecodeError as exc:
        raise CalibrationError(f"{label}: not TOML ({exc})") from None
    if not isinstance(table, dict):
        raise CalibrationError(f"{label}: no [camera] table; {_keys_text()}")
    sessions = table.pop("sessions", {})
    if not isinstance(sessions, dict) or not all(isinstance(v, dict) for v in sessions.values()):
        raise CalibrationError(f"{label}: [camera.sessions] must hold one table per session")
    first = _setup(table, label, "[camera]")
    moved = "camera" if first.mode == "eye_to_hand" else "target"
    out = {}
    for name, pose in sessions.items():
        keys = {f"{moved}_xyz_mm", f"{moved}_rpy_deg"}
        where = f"[camera.sessions.{name}]"
        if set(pose) != keys:
            raise CalibrationError(
                f"{label}: {where} gives {', '.join(sorted(keys))}: the {moved}'s pose of that "
                f"placement ({first.mode}), nothing else"
            )
        whole = {**_setup_keys(first), **pose}
        out[name] = _setup(whole, label, where)
    return first, out


def _setup(table: dict, label: str, where: str) -> CameraSetup:
    """A `CameraSetup` from a ``[camera]`` table (`CAMERA_KEYS`)."""
    from ..model.frames import matrix_from_rpy
    from .camera import Intrinsics
    from .target import Checkerboard

    optional = {"distortion"}
    missing = [k for k in CAMERA_KEYS if k not in table and k not in optional]
    unknown = [k for k in table if k not in CAMERA_KEYS]
    if missing or unknown:
        what = f"missing {', '.join(missing)}" if missing else f"unknown {', '.join(unknown)}"
        raise CalibrationError(f"{label}: {where} {what}; {_keys_text()}")

    def numbers(key, n):
        value = table[key]
        if (
            not isinstance(value, list)
            or len(value) != n
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
        ):
            raise CalibrationError(f"{label}: {where} {key} must be {n} numbers")
        return np.array(value, dtype=float)

    def pose(prefix):
        T = np.eye(4)
        T[:3, :3] = matrix_from_rpy(np.radians(numbers(f"{prefix}_rpy_deg", 3)))
        T[:3, 3] = numbers(f"{prefix}_xyz_mm", 3) * 1e-3
        return T

    for key in ("fx", "fy", "cx", "cy", "board_spacing_mm"):
        if isinstance(table[key], bool) or not isinstance(table[key], int | float):
            raise CalibrationError(f"{label}: {where} {key} must be a number, not text")
    size = numbers("image_size", 2)
    if np.any(size != np.round(size)):
        raise CalibrationError(f"{label}: {where} image_size must be whole pixels")
    distortion = numbers("distortion", 5) if "distortion" in table else np.zeros(5)
    shape = (int(size[0]), int(size[1]))
    try:
        lens = Intrinsics(table["fx"], table["fy"], table["cx"], table["cy"], *distortion)
        spacing = table["board_spacing_mm"] * 1e-3
        board = Checkerboard(table["board_rows"], table["board_cols"], spacing)
        return CameraSetup(table["mode"], pose("camera"), pose("target"), lens, board, shape)
    except CalibrationError as exc:
        raise CalibrationError(f"{label}: {where} {exc}") from None


def _setup_keys(setup: CameraSetup) -> dict:
    """`setup` as the values of a ``[camera]`` table (`CAMERA_KEYS`)."""
    from ..model.frames import rpy_from_matrix

    lens = setup.intrinsics
    return {
        "mode": setup.mode,
        "camera_xyz_mm": (setup.camera[:3, 3] * 1e3).tolist(),
        "camera_rpy_deg": np.degrees(rpy_from_matrix(setup.camera[:3, :3])).tolist(),
        "target_xyz_mm": (setup.target[:3, 3] * 1e3).tolist(),
        "target_rpy_deg": np.degrees(rpy_from_matrix(setup.target[:3, :3])).tolist(),
        "fx": lens.fx,
        "fy": lens.fy,
        "cx": lens.cx,
        "cy": lens.cy,
        "distortion": [lens.k1, lens.k2, lens.p1, lens.p2, lens.k3],
        "image_size": list(setup.image_size),
        "board_rows": setup.board.rows,
        "board_cols": setup.board.cols,
        "board_spacing_mm": setup.board.spacing * 1e3,
    }


def camera_text(setup: CameraSetup, comment: str = "", sessions=None) -> str:
    """The TOML text of `setup` (and of later placements, `sessions`: label → CameraSetup,
    only their moved pose written) that `read_cameras` reads back (poses to 1e-12 mm, deg)."""

    def value(v) -> str:
        if isinstance(v, str):
            return f'"{v}"'
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return f"{v:.17g}" if isinstance(v, float) else str(v)

    lines = [f"# {line}" for line in comment.splitlines()] + ["[camera]"]
    lines += [f"{k} = {value(v)}" for k, v in _setup_keys(setup).items()]
    moved = "camera" if setup.mode == "eye_to_hand" else "target"
    for label, other in (sessions or {}).items():
        keys = _setup_keys(other)
        lines += ["", f"[camera.sessions.{label}]"]
        lines += [f"{k} = {value(keys[k])}" for k in (f"{moved}_xyz_mm", f"{moved}_rpy_deg")]
    return "\n".join(lines) + "\n"


def _keys_text() -> str:
    return "give " + "; ".join(f"{k} ({v})" for k, v in CAMERA_KEYS.items())
