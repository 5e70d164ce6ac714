"""Calibration targets (boards) and their geometry, declared as a one-line string.

* ``chessboard:COLSxROWS:SQUARE_M`` — COLS × ROWS *inner* corners (OpenCV's pattern size),
  squares SQUARE_M metres.  Corner id ``r·COLS + c`` sits at ``(c·s, r·s, 0)``.
* ``charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT`` — COLS × ROWS *squares* (`cv2.aruco.CharucoBoard`),
  markers MARKER_M metres, DICT an OpenCV dictionary name (``DICT_5X5_100``, ``5X5_100``…).
  Corner ids and positions are the board's own (`getChessboardCorners`).
* ``aprilgrid:COLSxROWS:TAG_M:SPACING_RATIO:DICT`` — COLS × ROWS tags of TAG_M metres spaced by
  SPACING_RATIO·TAG_M (Kalibr's convention), ids 0… row by row (`cv2.aruco.GridBoard`); DICT
  default ``DICT_APRILTAG_36h11``.  Corner id ``4·tag + j``, j the tag's corner in OpenCV's order.

Board frame: origin at corner 0 (chessboard) or the board's own origin (OpenCV's boards),
z = 0 on the board plane; points in m.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from pipeline.errors import RobocalError

KINDS = ("chessboard", "charuco", "aprilgrid")


@dataclass(frozen=True)
class Target:
    """A parsed target declaration (see module docstring)."""

    spec: str
    kind: str
    cols: int
    rows: int
    square_m: float
    marker_m: float = 0.0
    spacing_ratio: float = 0.0
    dictionary: str = ""

    @property
    def pattern_size(self) -> tuple[int, int]:
        return self.cols, self.rows

    def aruco_dictionary(self):
        import cv2

        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))

    @cached_property
    def board(self):
        """The OpenCV board object (charuco, aprilgrid); None for a chessboard."""
        import cv2

        if self.kind == "charuco":
            return cv2.aruco.CharucoBoard((self.cols, self.rows), self.square_m, self.marker_m,
                                          self.aruco_dictionary())
        if self.kind == "aprilgrid":
            return cv2.aruco.GridBoard((self.cols, self.rows), self.square_m, self.spacing_ratio * self.square_m,
                                       self.aruco_dictionary())
        return None

    @cached_property
    def points(self) -> np.ndarray:
        """Every corner's position in the board frame, (n_corners, 3) m, indexed by corner id."""
        if self.kind == "chessboard":
            c, r = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
            return np.c_[c.ravel() * self.square_m, r.ravel() * self.square_m, np.zeros(c.size)]
        if self.kind == "charuco":
            return np.asarray(self.board.getChessboardCorners(), float).reshape(-1, 3)
        return np.asarray(self.board.getObjPoints(), float).reshape(-1, 3)

    @property
    def n_corners(self) -> int:
        return len(self.points)


def _dict_name(name: str, spec: str) -> str:
    import cv2

    full = name if name.upper().startswith("DICT_") else f"DICT_{name}"
    for cand in (full, full.upper(), "DICT_" + full[5:].upper().replace("H", "h")):
        if hasattr(cv2.aruco, cand):
            return cand
    raise RobocalError(f"--target {spec!r}: unknown ArUco dictionary {name!r} (e.g. DICT_5X5_100, DICT_APRILTAG_36h11)")


def _size(part: str, spec: str) -> tuple[int, int]:
    try:
        c, r = (int(v) for v in part.lower().split("x"))
    except ValueError:
        raise RobocalError(f"--target {spec!r}: {part!r} is not COLSxROWS (e.g. 9x6)") from None
    if c < 2 or r < 2:
        raise RobocalError(f"--target {spec!r}: {part!r} needs at least 2 columns and 2 rows")
    return c, r


def _metres(part: str, what: str, spec: str) -> float:
    try:
        v = float(part)
    except ValueError:
        raise RobocalError(f"--target {spec!r}: {what} {part!r} is not a number (metres)") from None
    if not 0 < v < 10:
        raise RobocalError(f"--target {spec!r}: {what} {v} m is not a plausible size (0 < m < 10; mm given as m?)")
    return v


def parse(spec: str) -> Target:
    """A `Target` from its declaration (module docstring); one-line errors otherwise."""
    parts = spec.split(":")
    kind = parts[0].lower()
    need = {"chessboard": 3, "charuco": 5, "aprilgrid": (4, 5)}
    if kind not in KINDS:
        raise RobocalError(f"--target {spec!r}: expected chessboard:COLSxROWS:SQUARE_M, "
                           "charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT or aprilgrid:COLSxROWS:TAG_M:SPACING_RATIO[:DICT]")
    n = need[kind]
    if len(parts) not in (n if isinstance(n, tuple) else (n,)):
        raise RobocalError(f"--target {spec!r}: {kind} takes {n if isinstance(n, int) else n[-1]} fields separated by ':'")
    cols, rows = _size(parts[1], spec)
    if kind == "chessboard":
        return Target(spec, kind, cols, rows, _metres(parts[2], "square size", spec))
    if kind == "charuco":
        sq, mk = _metres(parts[2], "square size", spec), _metres(parts[3], "marker size", spec)
        if mk >= sq:
            raise RobocalError(f"--target {spec!r}: the marker ({mk} m) must be smaller than the square ({sq} m)")
        return Target(spec, kind, cols, rows, sq, mk, dictionary=_dict_name(parts[4], spec))
    try:
        ratio = float(parts[3])
    except ValueError:
        raise RobocalError(f"--target {spec!r}: spacing ratio {parts[3]!r} is not a number") from None
    if not 0 < ratio < 2:
        raise RobocalError(f"--target {spec!r}: spacing ratio {ratio} outside (0, 2)")
    d = _dict_name(parts[4] if len(parts) == 5 else "DICT_APRILTAG_36h11", spec)
    return Target(spec, kind, cols, rows, _metres(parts[2], "tag size", spec), spacing_ratio=ratio, dictionary=d)
