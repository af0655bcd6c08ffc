"""The calibration target: a checkerboard's inner corners in its own frame.

Convention (OpenCV's, for ``cv2.findChessboardCorners(image, (cols, rows))``): the board
frame has its origin at the first inner corner, x along a row (``cols`` corners), y along a
column (``rows`` corners), z = x × y, the board in the plane z = 0. Corner ``k = i · cols + j``
(row i, column j) is at ``(j · spacing, i · spacing, 0)``: row by row, each row left to
right — the order of OpenCV's detections and of the object points its tutorials build with
``np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * spacing``.

Seen in an upright image with x to the right and y down, z points away from the camera: the
printed face is the board's −z side (a camera sees it when the camera's centre has z < 0 in
the board frame).

The colours: the square diagonally outside corner 0 (around (−s/2, −s/2)) is black, and so is
every square whose row and column, counted from that one, add up to an even number.

A detector fixes this order only up to the board's symmetry (`Checkerboard.symmetric`). With
rows + cols odd the colours fix it: OpenCV (5.0 tested) returns this order at any turn of such a
board (tests/test_camera.py renders boards and checks). With rows + cols even (the 7 × 9
default) a board turned 180° about its z axis shows the same colours, and OpenCV returns the
corners in this order or reversed (k → n − 1 − k), depending on how the board is turned in
the image; with rows == cols a 90° turn is possible too. Put the detections in this order
before using them (e.g. the labelling nearest the prediction), or use a board with
rows + cols odd.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError

MAX_SPACING = 0.5
"""Side of a square (m) past which a board's spacing is taken for a unit slip."""

MIN_SPACING = 1e-3
"""Side of a square (m) below which a board's spacing is taken for a unit slip."""


@dataclass(frozen=True)
class Checkerboard:
    """A checkerboard of ``rows × cols`` inner corners, `spacing` m apart.

    Attributes
    ----------
    rows, cols : int
        Inner corners per column and per row (OpenCV's pattern size is ``(cols, rows)``);
        at least 2 each.
    spacing : float
        Side of a square, m; > 0.
    """

    rows: int = 7
    cols: int = 9
    spacing: float = 0.02

    def __post_init__(self) -> None:
        for name in ("rows", "cols"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 2:
                raise CalibrationError(
                    f"Checkerboard: {name} = {value!r}; give the number of inner corners, an "
                    "integer ≥ 2"
                )
            object.__setattr__(self, name, int(value))
        try:
            spacing = float(self.spacing)
        except (TypeError, ValueError):
            spacing = math.nan
        if not (math.isfinite(spacing) and spacing > 0):
            raise CalibrationError(
                f"Checkerboard: spacing = {self.spacing!r}; give the side of a square in m, > 0"
            )
        if spacing < MIN_SPACING:
            raise CalibrationError(
                f"Checkerboard: spacing = {spacing:g} m, a square smaller than "
                f"{MIN_SPACING * 1e3:g} mm; the side of a square in m (m for mm? "
                f"{spacing:g} m is {spacing * 1e3:g} mm)"
            )
        if spacing > MAX_SPACING:
            raise CalibrationError(
                f"Checkerboard: spacing = {spacing:g} m, a square larger than {MAX_SPACING:g} m; "
                f"the side of a square in m (mm for m? {spacing:g} mm is {spacing * 1e-3:g} m)"
            )
        object.__setattr__(self, "spacing", spacing)

    @property
    def n_corners(self) -> int:
        """rows · cols."""
        return self.rows * self.cols

    @property
    def pattern_size(self) -> tuple[int, int]:
        """OpenCV's ``patternSize`` for this board: (cols, rows)."""
        return (self.cols, self.rows)

    @property
    def symmetric(self) -> bool:
        """Whether a detector can return the corners in another order than `corners`: a
        180° turn keeps the colouring when rows + cols is even, a 90° turn when rows == cols."""
        return (self.rows + self.cols) % 2 == 0 or self.rows == self.cols

    @property
    def centre(self) -> np.ndarray:
        """The middle of the corner grid in the board frame, m, shape (3,)."""
        return np.array([(self.cols - 1) / 2, (self.rows - 1) / 2, 0.0]) * self.spacing

    def corners(self) -> np.ndarray:
        """The inner corners in the board frame, m, shape (rows · cols, 3), in the module's
        order: corner ``i · cols + j`` at ``(j · spacing, i · spacing, 0)``."""
        i, j = np.divmod(np.arange(self.n_corners), self.cols)
        return np.stack([j * self.spacing, i * self.spacing, np.zeros(self.n_corners)], axis=1)
