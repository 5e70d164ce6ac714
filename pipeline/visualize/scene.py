"""Geometry of the 3-D scene, as pure functions of models and measurements (m, jig frame {W}).

Nothing here talks to rerun: these return arrays that `pipeline.visualize.recording` logs.
"""

from __future__ import annotations

import re

import numpy as np

from pipeline.models import serial_arm
from pipeline.models.jig import Face, Jig


def jig_blocks(jig: Jig) -> tuple[np.ndarray, np.ndarray]:
    """Solid blocks of a stepped jig: one box per upward face (a step top), reaching down to the
    lowest face and out to the nearest side faces.  Returns mins (B,3) and sizes (B,3), m."""
    tops = [f for f in jig.faces if f.axis == "z" and f.normal_sign > 0]
    z0 = min([f.coordinate for f in jig.faces if f.axis == "z" and f.normal_sign < 0] + [0.0])
    mins, sizes = [], []
    for top in tops:
        lo, hi = np.zeros(3), np.zeros(3)
        for ax, (a, b) in zip((0, 1), top.extent):
            planes = sorted(f.coordinate for f in jig.faces if f.axis_index == ax)
            below = [c for c in planes if c <= a]
            above = [c for c in planes if c >= b]
            lo[ax] = below[-1] if below else a
            hi[ax] = above[0] if above else b
        lo[2], hi[2] = z0, top.coordinate
        mins.append(lo)
        sizes.append(hi - lo)
    return np.array(mins).reshape(-1, 3), np.array(sizes).reshape(-1, 3)


def face_outline(face: Face) -> np.ndarray:
    """Closed rectangle (5,3) of a face's extent on its plane, m."""
    i, j = face.other_axes()
    (a0, a1), (b0, b1) = face.extent
    pts = np.zeros((5, 3))
    pts[:, face.axis_index] = face.coordinate
    pts[:, i] = [a0, a1, a1, a0, a0]
    pts[:, j] = [b0, b0, b1, b1, b0]
    return pts


def arm_polylines(x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Line strips through the base, every joint frame and the tool tip: (N, n_joints + 2, 3), m."""
    return serial_arm.frames(np.asarray(x, float), np.atleast_2d(q))[:, :, :3, 3]


def pick_poses(n: int, k: int = 5) -> np.ndarray:
    """Indices of k measurement poses spread evenly over n (all of them if n ≤ k)."""
    if n <= k:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, k).round().astype(int))


def touch_residual_vectors(residuals: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """3-D vectors (n,3), m, from a touch model's predicted tip to its face along the face axis:
    −r·e_axis for residual r = p_axis − coordinate."""
    r = np.asarray(residuals, float).reshape(-1)
    v = np.zeros((r.size, 3))
    v[np.arange(r.size), np.asarray(axis, int)] = -r
    return v


def decimate(t_ns: np.ndarray, rate_hz: float) -> np.ndarray:
    """Indices of a stream sampled at about `rate_hz` (first sample of each period)."""
    t = np.asarray(t_ns, np.int64)
    if t.size == 0:
        return np.zeros(0, int)
    bins = (t - t[0]) // int(1e9 / rate_hz)
    return np.flatnonzero(np.r_[True, np.diff(bins) > 0])


def entity_part(label: str) -> str:
    """A group label as one entity-path part (a channel name such as /tracker/point → tracker_point,
    "target 0" → target_0: rerun's entity paths take no unescaped whitespace)."""
    part = "_".join(p for p in re.split(r"[/\s]+", str(label)) if p)
    return part or "all"
