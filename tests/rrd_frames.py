"""Test helper: the named-frame transforms of a .rrd read back with rerun's own reader (rerun.chunk.RrdReader):
every static transform (parent, child, 4×4) and every time-stamped one, and a frame's pose in another by
walking parents up (float32 as rerun stores them)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
from rerun.chunk import RrdReader
from scipy.spatial.transform import Rotation


def _flat(v):
    while isinstance(v, list) and len(v) == 1 and isinstance(v[0], list):
        v = v[0]
    return v[0] if isinstance(v, list) and len(v) == 1 else v


def _matrix(tr, qt) -> np.ndarray:
    T = np.eye(4)
    if qt is not None:
        T[:3, :3] = Rotation.from_quat(np.asarray(qt, float)).as_matrix()
    if tr is not None:
        T[:3, 3] = np.asarray(tr, float)
    return T


def read_frames(path: Path) -> tuple[dict, dict]:
    """(static: child → (parent, 4×4), timed: child → (parent, times ns (N,), (N, 4, 4)) sorted by time)."""
    static: dict = {}
    timed: dict = {}
    for chunk in RrdReader(path).stream():
        b = chunk.to_record_batch()
        names = b.schema.names
        if "Transform3D:child_frame" not in names:
            continue
        col = lambda n: b.column(n).to_pylist() if n in names else [None] * b.num_rows  # noqa: E731
        child, parent = col("Transform3D:child_frame"), col("Transform3D:parent_frame")
        tr, qt = col("Transform3D:translation"), col("Transform3D:quaternion")
        times = None
        if "time" in names:
            arr = b.column("time")
            times = (arr.cast(pa.int64()) if pa.types.is_timestamp(arr.type) else arr).to_pylist()
        for i in range(b.num_rows):
            c, p = _flat(child[i]), _flat(parent[i])
            if c is None:
                continue
            T = _matrix(_flat(tr[i]), _flat(qt[i]))
            if chunk.is_static or times is None:
                static[c] = (p, T)
            else:
                timed.setdefault(c, [p, [], []])
                timed[c][1].append(times[i])
                timed[c][2].append(T)
    out = {}
    for c, (p, t, Ts) in timed.items():
        o = np.argsort(t)
        out[c] = (p, np.asarray(t, np.int64)[o], np.asarray(Ts)[o])
    return static, out


def pose(static: dict, timed: dict, frame: str, to: str, k: int) -> np.ndarray:
    """Pose of `frame` in `to` at the k-th time step of the timed transforms."""
    T = np.eye(4)
    f = frame
    while f != to:
        if f in timed:
            p, _, Ts = timed[f]
            T = Ts[k] @ T
        elif f in static:
            p, M = static[f]
            T = M @ T
        else:
            raise KeyError(f"{frame}: no transform up to {to} (stops at {f})")
        f = p
    return T
