"""Batched rigid transforms (numpy, SI units).

Every function takes angles in rad and lengths in m and broadcasts over a leading
batch axis, so a whole campaign is transformed in one call.
"""

from __future__ import annotations

import numpy as np

AXES = {"x": 0, "y": 1, "z": 2}


def rot(axis: str, angle: np.ndarray | float) -> np.ndarray:
    """Rotation matrices about a principal axis: shape (..., 3, 3)."""
    a = np.asarray(angle, dtype=float)
    c, s = np.cos(a), np.sin(a)
    one, zero = np.ones_like(a), np.zeros_like(a)
    if axis == "x":
        rows = ((one, zero, zero), (zero, c, -s), (zero, s, c))
    elif axis == "y":
        rows = ((c, zero, s), (zero, one, zero), (-s, zero, c))
    elif axis == "z":
        rows = ((c, -s, zero), (s, c, zero), (zero, zero, one))
    else:
        raise ValueError(f"unknown axis {axis!r}")
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def homogeneous(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Stack rotation (...,3,3) and translation (...,3) into (...,4,4)."""
    R = np.asarray(R, dtype=float)
    p = np.asarray(p, dtype=float)
    shape = np.broadcast_shapes(R.shape[:-2], p.shape[:-1])
    T = np.zeros(shape + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = p
    T[..., 3, 3] = 1.0
    return T


def trans(x: float, y: float, z: float) -> np.ndarray:
    """Pure translation as a 4x4 homogeneous transform."""
    return homogeneous(np.eye(3), np.array([x, y, z], dtype=float))


def hrot(axis: str, angle: np.ndarray | float) -> np.ndarray:
    """Pure rotation as (...,4,4) homogeneous transforms."""
    R = rot(axis, angle)
    return homogeneous(R, np.zeros(R.shape[:-2] + (3,)))
