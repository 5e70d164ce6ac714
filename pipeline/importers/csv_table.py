"""CSV measurement tables → robocal recordings (`robocal import csv`).

Columns are matched to the URDF chain's joints by header name (any order; other columns are
measurement columns or ignored).  Units are declared (`joint_units` deg|rad for revolute joints,
`length_units` mm|m for prismatic joints and positions) and converted to SI; a value beyond a
joint's limits after conversion — the usual sign of degrees declared as radians — is an error
naming file, row and column (`pipeline.importers.bounds`: the ranges and numeric bounds every
importer shares; a reading past its limit by less than that range's slack is a warning).  A joint
driven by others (`coupled`) has no column of its own unless `coupling_wins`.  Several files may be
given: their rows are concatenated and each row keeps its file's stem (the plane or group name for plane / coincidence measurements).
Optional columns ``dir_<joint>`` (−1/0/+1, point measurements) give each joint's direction of approach
(`approach`): the sign of its last motion before the standstill, 0 unknown — what backlash needs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.errors import RobocalError
from pipeline.importers.bounds import check_bound, joint_range
from pipeline.importers.csv_text import numbers, read_columns
from pipeline.models.urdf import RobotDescription


@dataclass(frozen=True)
class CsvSpec:
    """How to read the measurement columns (names refer to CSV headers)."""

    measure: str
    joint_units: str = "rad"
    length_units: str = "m"
    columns: tuple[str, ...] = ()  # header for files without one
    position: tuple[str, ...] = ("x", "y", "z")
    targets: tuple[tuple[str, str, str], ...] = ()  # further targets' position columns
    orientation: tuple[str, ...] = ()
    orientation_kind: str = "rpy"  # rpy (URDF roll, pitch, yaw; rad) | quat (x, y, z, w)
    group_from: str = "file"  # coincidence: "file" (stem) or "parent/file"
    planes: dict = field(default_factory=dict)  # plane name (file stem) -> {"normal": (3,), "offset": col or value}
    coupled: tuple[str, ...] = ()  # joints driven by others (--coupled): no column of their own ...
    coupling_wins: bool = False  # ... unless the user says the coupling replaces it (--coupling-wins)


def _numeric(path: Path, cols: dict, name: str, scale: float = 1.0) -> np.ndarray:
    """The column `name` in SI (× `scale`): finite, within ±BOUND, else one line naming file, row and column."""
    v = numbers(path, name, cols[name]) * scale
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size:
        raise RobocalError(f"{path}: row {bad[0] + 2}: column {name!r} is empty, NaN or inf")
    check_bound(path, name, v)
    return v


def approach(path: Path, cols: dict, names: list[str], n: int) -> np.ndarray:
    """(n, n_joints) int8 direction of approach of each joint at each row from the optional columns
    ``dir_<joint>`` (−1: the joint last moved towards lower values, +1: towards higher, 0 or no column:
    unknown); any other value is one line naming file, row and column."""
    out = np.zeros((n, len(names)), np.int8)
    for k, j in enumerate(names):
        c = f"dir_{j}"
        if c not in cols:
            continue
        v = numbers(path, c, cols[c])
        bad = np.flatnonzero(~np.isin(v, (-1.0, 0.0, 1.0)))
        if bad.size:
            raise RobocalError(f"{path}: row {bad[0] + 2}: column {c!r}: {v[bad[0]]!r} is not -1, 0 or +1 "
                               "(the joint's direction of approach)")
        out[:, k] = v.astype(np.int8)
    return out


def _need(path: Path, header: list[str], names: list[str], what: str, used: set[str]) -> None:
    missing = [c for c in names if c not in header]
    if missing:
        unknown = [c for c in header if c not in used and c not in names]
        more = f", … ({len(unknown) - 20} more)" if len(unknown) > 20 else ""
        raise RobocalError(f"{path}: missing {what} column(s) {', '.join(missing)}"
                           f"{'; unused columns: ' + ', '.join(unknown[:20]) + more if unknown else ''}")


def read_table(paths: list[Path], desc: RobotDescription, spec: CsvSpec) -> tuple[dict[str, np.ndarray], dict]:
    """The measurement table (SI, chain joint order) of the CSV files, and campaign extras."""
    joints = desc.movable
    names = [j.name for j in joints]
    ang = np.array([j.type != "prismatic" for j in joints])
    jscale = np.where(ang, np.pi / 180 if spec.joint_units == "deg" else 1.0,
                      1e-3 if spec.length_units == "mm" else 1.0)
    lscale = 1e-3 if spec.length_units == "mm" else 1.0
    lo, hi = np.array([j.lower for j in joints]), np.array([j.upper for j in joints])
    rows: dict[str, list] = {}
    planes = []
    warnings: list[str] = []
    for path in paths:
        path = Path(path)
        used = set(spec.position) | {c for t in spec.targets for c in t} | set(spec.orientation)
        pl_off = spec.planes.get(path.stem, {}).get("offset")
        keep = set(names) | used | ({pl_off} if isinstance(pl_off, str) else set()) | {f"dir_{j}" for j in names}
        header, cols, n = read_columns(path, keep, spec.columns)
        if n == 0:
            raise RobocalError(f"{path}: no data rows")
        _need(path, header, names, "joint", used)
        own = [c for c in spec.coupled if c in header]
        if own and not spec.coupling_wins:
            raise RobocalError(f"{path}: column {own[0]!r}: joint {own[0]!r} is given to --coupled but has its own "
                               f"column; drop --coupled {own[0]} (the column wins) or add --coupling-wins (the "
                               "coupling replaces the column)")
        q = np.stack([_numeric(path, cols, c, s) for c, s in zip(names, jscale)], axis=1)
        lo_e, hi_e = joint_range(lo, hi, ang)
        out_of = (q < lo_e) | (q > hi_e)
        beyond = ((q < lo) | (q > hi)) & ~out_of
        for k in np.flatnonzero(beyond.any(0)):
            warnings.append(f"{path}: column {names[k]!r}: {int(beyond[:, k].sum())} row(s) beyond the URDF limits "
                            f"[{lo[k]:.6g}, {hi[k]:.6g}] (at most {np.max(np.maximum(lo[k] - q[:, k], q[:, k] - hi[k])):.3g})")
        if out_of.any():
            i, k = np.argwhere(out_of)[0]
            hint = " (degrees declared as radians? use --joint-units deg)" if ang[k] and spec.joint_units == "rad" else ""
            raise RobocalError(f"{path}: row {i + 2}: column {names[k]!r}: {q[i, k]:.6g} is far outside the joint's "
                               f"limits [{lo[k]:.6g}, {hi[k]:.6g}]{hint}")
        part: dict[str, np.ndarray] = {"joint_positions": q}
        if any(f"dir_{j}" in cols for j in names):
            if spec.measure != "point":
                raise RobocalError(f"{path}: direction columns dir_<joint> need --measure point (got {spec.measure})")
            part["approach"] = approach(path, cols, names, n)
        if spec.measure in ("point", "pose"):
            _need(path, header, list(spec.position), "position", set(names))
            pos = [np.stack([_numeric(path, cols, c, lscale) for c in spec.position], 1)]
            for t in spec.targets:
                _need(path, header, list(t), "target position", set(names))
                pos.append(np.stack([_numeric(path, cols, c, lscale) for c in t], 1))
            part["position"] = np.concatenate(pos)
            part["target"] = np.repeat(np.arange(len(pos)), n)
            part["joint_positions"] = np.tile(q, (len(pos), 1))
            if "approach" in part:
                part["approach"] = np.tile(part["approach"], (len(pos), 1))
        if spec.measure == "pose":
            _need(path, header, list(spec.orientation), "orientation", set(names))
            o = np.stack([_numeric(path, cols, c) for c in spec.orientation], 1)
            if spec.orientation_kind == "rpy":  # URDF rpy: R = Rz(yaw) Ry(pitch) Rx(roll)
                part["orientation"] = Rotation.from_euler("ZYX", o[:, ::-1]).as_quat()
            else:
                part["orientation"] = o / np.linalg.norm(o, axis=1, keepdims=True)
            del part["target"]
        if spec.measure == "plane":
            stem = path.stem
            if stem not in spec.planes:
                raise RobocalError(f"{path}: no plane declared for this file (--plane {stem}:NX,NY,NZ:OFFSET)")
            pl = spec.planes[stem]
            off = pl["offset"]
            if isinstance(off, str):
                _need(path, header, [off], "plane offset", set(names))
                v = _numeric(path, cols, off, lscale)
                if np.ptp(v) > 1e-9:
                    raise RobocalError(f"{path}: column {off!r} (plane offset) differs between rows")
                off = float(v[0])
            planes.append({"name": stem, "normal": list(pl["normal"]), "offset": float(off), "known": pl.get("known", True)})
            part["plane"] = np.full(n, stem, object)
        if spec.measure == "coincidence":
            g = path.stem if spec.group_from == "file" else f"{path.parent.name}/{path.stem}"
            part["group"] = np.full(n, g, object)
        for k, v in part.items():
            rows.setdefault(k, []).append(v)
    table = {k: np.concatenate(v) for k, v in rows.items()}
    extras: dict = {"import_warnings": warnings} if warnings else {}
    if planes:
        extras["planes"] = planes
    if spec.measure == "point":
        extras["n_targets"] = 1 + len(spec.targets)
    return table, extras
