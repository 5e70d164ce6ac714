"""Device clock → host clock: offset and drift from the lower envelope of receive times.

Every frame carries the device's send time d; the host stamps its receive time h.  h − d
is the clock offset plus a transport latency that is never negative and often far larger
than its floor (buffering, scheduling).  The lower envelope of the points (d, h) — the
line under every point that minimises the summed distance to them (Moon, Skelly & Towsley,
1999: an LP whose optimum is the lower convex-hull edge spanning the mean of d) — follows
offset and drift while ignoring late frames.  The hull comes from scipy (qhull); only the
hull's vertices are kept between updates, so the estimator is O(new points) per update.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

MIN_SPAN_S = 0.05  # device-time span below which only an offset is estimated


def lower_hull(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Indices of the lower convex hull of points (x, y), left to right."""
    if x.size < 3:
        return np.argsort(x, kind="stable")
    try:
        hull = ConvexHull(np.column_stack([x, y]))
    except QhullError:  # all points collinear (or coincident)
        order = np.lexsort((y, x))
        return order[[0, -1]] if x.size > 1 else order
    v = hull.vertices  # counter-clockwise for 2-D
    xv, yv = x[v], y[v]
    start = int(np.lexsort((yv, xv))[0])  # leftmost, lowest
    stop = int(np.lexsort((yv, -xv))[0])  # rightmost, lowest
    v = np.roll(v, -start)
    k = (stop - start) % v.size
    return v[:k + 1]


def envelope_line(x: np.ndarray, y: np.ndarray, x_mean: float) -> tuple[float, float]:
    """(a, b) of the lower-envelope line y = a + b x: the hull edge spanning `x_mean`."""
    h = lower_hull(x, y)
    hx, hy = x[h], y[h]
    if h.size < 2 or hx[-1] - hx[0] < MIN_SPAN_S:
        return float(np.min(y)), 0.0
    k = int(np.clip(np.searchsorted(hx, x_mean) - 1, 0, h.size - 2))
    b = (hy[k + 1] - hy[k]) / (hx[k + 1] - hx[k])
    return float(hy[k] - b * hx[k]), float(b)


@dataclass
class ClockFit:
    """host_ns ≈ h0 + (d − d0) + (offset_s + drift · (d − d0)/1e9)·1e9."""

    d0: int
    h0: int
    offset_s: float
    drift: float  # dimensionless (1e-4 = 100 ppm); includes any playback speed-up
    n: int

    def to_host(self, d_ns: np.ndarray) -> np.ndarray:
        dd = np.asarray(d_ns, dtype=np.int64) - self.d0
        x = dd / 1e9
        return self.h0 + dd + np.round((self.offset_s + self.drift * x) * 1e9).astype(np.int64)

    def as_dict(self) -> dict:
        return {"device_ref_ns": int(self.d0), "host_ref_ns": int(self.h0),
                "offset_ns": int(self.h0 - self.d0 + round(self.offset_s * 1e9)),
                "drift_ppm": self.drift * 1e6, "points": self.n}


class ClockSync:
    """Online estimator of one device clock: `add` (device send time, host receive time)
    pairs, `fit()` the current line."""

    def __init__(self) -> None:
        self.d0: int | None = None
        self.h0 = 0
        self._x = np.empty(0)  # kept points: hull vertices + new, s since d0
        self._y = np.empty(0)  # (h − h0) − (d − d0), s
        self._new_x: list[np.ndarray] = []
        self._new_y: list[np.ndarray] = []
        self._sum_x = 0.0
        self.n = 0

    def add(self, d_ns: np.ndarray | int, h_ns: np.ndarray | int) -> None:
        d = np.atleast_1d(np.asarray(d_ns, dtype=np.int64))
        h = np.broadcast_to(np.asarray(h_ns, dtype=np.int64), d.shape)
        if d.size == 0:
            return
        if self.d0 is None:
            self.d0, self.h0 = int(d[0]), int(h[0])
        dd = d - self.d0
        x = dd / 1e9
        self._new_x.append(x)
        self._new_y.append(((h - self.h0) - dd) / 1e9)
        self._sum_x += float(x.sum())
        self.n += d.size

    def fit(self) -> ClockFit | None:
        if self.d0 is None:
            return None
        if self._new_x:
            x = np.concatenate([self._x, *self._new_x])
            y = np.concatenate([self._y, *self._new_y])
            self._new_x, self._new_y = [], []
            keep = lower_hull(x, y)
            self._x, self._y = x[keep], y[keep]
        a, b = envelope_line(self._x, self._y, self._sum_x / self.n)
        return ClockFit(self.d0, self.h0, a, b, self.n)
