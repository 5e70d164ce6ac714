"""Where a held-out posture lies relative to the postures a calibration was fitted on (pure numpy).

A calibration predicts a posture it has (nearly) seen differently from one between its training postures, and
from one beyond them.  Each posture of an evaluated recording falls in one group:

* ``repeated``: every joint within `repeat_tol` (rad, or m for a prismatic joint) of one training posture —
  the same configuration on another occasion (what it measures is day-to-day repeatability);
* ``new``: not repeated, every joint inside the training range widened by `margin` on both sides
  (interpolation);
* ``out_of_range``: some joint outside that range (extrapolation).

The defaults (0.01 and 0.05) are those of FIGAROH's frozen TIAGo held-out protocol, whose published posture
counts this definition reproduces on its sessions.
"""

from __future__ import annotations

import numpy as np

GROUPS = ("repeated", "new", "out_of_range")
REPEAT_TOL = 0.01  # rad (m for prismatic joints)
RANGE_MARGIN = 0.05  # rad (m)


def posture_groups(q_train: np.ndarray, q: np.ndarray, repeat_tol: float = REPEAT_TOL,
                   margin: float = RANGE_MARGIN) -> np.ndarray:
    """Index into `GROUPS` of each posture of `q` (n, joints) relative to the training postures `q_train`
    (m, joints), both in rad / m in the same joint order."""
    q_train, q = np.atleast_2d(np.asarray(q_train, float)), np.atleast_2d(np.asarray(q, float))
    if q_train.shape[1] != q.shape[1]:
        raise ValueError(f"training postures have {q_train.shape[1]} joints, evaluated ones {q.shape[1]}")
    if not len(q_train):
        raise ValueError("no training postures")
    out = np.empty(len(q), int)
    for s in range(0, len(q), 256):  # blocks bound the (block, m, joints) difference array
        d = np.abs(q[s:s + 256, None, :] - q_train[None, :, :]).max(axis=2)
        out[s:s + 256] = np.where(d.min(axis=1) <= repeat_tol, 0, -1)
    lo, hi = q_train.min(axis=0) - margin, q_train.max(axis=0) + margin
    inside = np.all((q >= lo) & (q <= hi), axis=1)
    return np.where(out == 0, 0, np.where(inside, 1, 2))


def labels(q_train: np.ndarray, q: np.ndarray) -> np.ndarray:
    """`GROUPS` name of each posture (object array)."""
    return np.asarray(GROUPS, object)[posture_groups(q_train, q)]
