"""The numeric bounds every importer applies to what it reads (`import csv`, `import ros2`, `import
images`, `compensate --targets`): one rule, one wording, whatever the file format.

A value read as a measurement or a joint reading must be finite and, after the declared units are
converted to SI, within ±`BOUND` (1e6 m or rad: a million metres or radians is damage, not a
measurement).  A joint reading is also checked against its joint: an angle beyond ±`MAX_ANGLE`
(4π, two turns) on a joint without limits, or beyond its URDF limits by more than `LIMIT_SLACK` of
its range, is refused — the usual sign of degrees declared as radians.  Each refusal is one
`RobocalError` line naming the file and the row (or record) and the column (or field).
"""

from __future__ import annotations

import numpy as np

from pipeline.errors import RobocalError

BOUND = 1e6  # |value| of a coordinate or joint value (m or rad) read from a file: anything larger is damage
MAX_ANGLE = 4 * np.pi  # |angle| of a revolute joint without limits, rad: beyond is degrees or damage
LIMIT_SLACK = 0.25  # a reading beyond its URDF limit by more than this fraction of the range is an error


def first_beyond(v: np.ndarray) -> int | None:
    """Index of the first finite value of `v` (flattened) beyond ±BOUND, else None."""
    bad = np.flatnonzero(np.isfinite(v) & (np.abs(v) > BOUND))
    return int(bad[0]) if bad.size else None


def check_values(where, v: np.ndarray, unit: str = "m or rad") -> None:
    """One line when a value of `v` (one per record) is not finite or beyond ±BOUND; `where(i)`: the
    file and record of value i in the caller's words (e.g. 'bag: topic /p: record 3: position x')."""
    v = np.asarray(v, float)
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size:
        raise RobocalError(f"{where(int(bad[0]))}: {v[bad[0]]!r} is not a finite number")
    i = first_beyond(v)
    if i is not None:
        raise RobocalError(f"{where(i)}: {v[i]:.6g} is beyond ±{BOUND:g} ({unit}): not a measurement")


def check_bound(path, column: str, v: np.ndarray, first_line: int = 2, unit: str = "m or rad") -> None:
    """One line when a finite value of a CSV column is beyond ±BOUND (after unit conversion): names
    the file, the row (its line: data row i is line i + `first_line`) and the column."""
    i = first_beyond(np.asarray(v, float))
    if i is not None:
        raise RobocalError(f"{path}: row {i + first_line}: column {column!r}: {v[i]:.6g} is beyond "
                           f"±{BOUND:g} ({unit}): not a measurement")


def joint_range(lower: np.ndarray, upper: np.ndarray, angular: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lowest, highest) reading accepted per joint: the URDF limits widened by LIMIT_SLACK of the range,
    or ±MAX_ANGLE for a revolute joint without limits (a prismatic one without limits: ±BOUND)."""
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    finite = np.isfinite(hi - lo)
    slack = np.where(finite, LIMIT_SLACK * np.where(finite, hi - lo, 0.0), 0.0)
    lo_e = np.where(finite, lo - slack, np.where(angular, -MAX_ANGLE, -BOUND))
    hi_e = np.where(finite, hi + slack, np.where(angular, MAX_ANGLE, BOUND))
    return lo_e, hi_e


def check_joints(q: np.ndarray, names: list[str], lower, upper, angular, where, degrees_hint: str = "") -> None:
    """One line at the first reading of `q` (n, J; rad / m) outside `joint_range`; `where(i, k)`: the file,
    row and column of reading (i, k) in the caller's words; `degrees_hint` is added for an angle (e.g.
    'use --joint-units deg')."""
    lo_e, hi_e = joint_range(lower, upper, angular)
    out = (q < lo_e) | (q > hi_e)
    if out.any():
        i, k = np.argwhere(out)[0]
        lim = (f"limits [{lower[k]:.6g}, {upper[k]:.6g}]" if np.isfinite(upper[k] - lower[k])
               else f"±{MAX_ANGLE:.4g} rad (no limits)")
        hint = f" (degrees given as radians?{' ' + degrees_hint if degrees_hint else ''})" if angular[k] else ""
        raise RobocalError(f"{where(int(i), int(k))}: {q[i, k]:.6g} is far outside the {lim} of joint {names[k]!r}{hint}")
