"""The natural groups of a measurement table: rows that share something no other row has, kept whole
by every subsample of the table (pure numpy).

* camera corners: one image — they share the robot's pose at it and the board's pose in the
  camera; a handful of corners from many images is not a camera calibration (OpenCV's start needs
  ≥ 4 corners of a view) and a held-out corner whose image is in the fit is not held out.  The
  model says so through its ``holdout_groups(data)`` hook;
* coincidences: one socket (``group``) — its point is a parameter only its own touches fix;
* points on several tips (``target`` with more than one tip): one posture — the tips read at the
  same joint positions (of the same session).

`holdout_groups` is what a k-fold held-out split keeps together (the model's hook: camera
images); `natural_groups` adds the sockets and postures, which a *subsample* must keep whole but
a k-fold split may not (a socket held out whole has no fitted point: `group_holdout` leaves such
groups out with their own parameters refitted instead).  `whole_groups` picks a subsample of whole
groups spread evenly over the table.
"""

from __future__ import annotations

import numpy as np

from pipeline.identify.model import Table, n_rows


def holdout_groups(model, data: Table) -> np.ndarray | None:
    """Rows a held-out split keeps together (a camera image's corners), from the model's optional
    ``holdout_groups`` hook; None: rows are split one by one."""
    hook = getattr(model, "holdout_groups", None)
    return None if hook is None else np.asarray(hook(data))


def natural_groups(model, data: Table) -> np.ndarray:
    """Group index (n,) int of each row (module docstring); each row its own group where the table has none."""
    n = n_rows(data)
    g = holdout_groups(model, data)
    if g is None and "group" in data and np.ndim(data["group"]) == 1:  # coincidences: the socket
        g = np.asarray(data["group"])
    if g is None and "target" in data and np.unique(np.asarray(data["target"])).size > 1 and "joint_positions" in data:
        q = np.asarray(data["joint_positions"], float).reshape(n, -1)  # several tips: the posture
        ses = np.unique(np.asarray(data["session"]).astype(str), return_inverse=True)[1].reshape(n, 1) \
            if "session" in data else np.zeros((n, 1))
        g = np.unique(np.hstack([ses, q]), axis=0, return_inverse=True)[1].ravel()
    if g is None:
        return np.arange(n)
    return np.unique(g, return_inverse=True)[1].ravel()


def whole_groups(groups: np.ndarray, min_rows: int, min_groups: int = 1) -> np.ndarray:
    """Sorted row indices of whole groups spread evenly over the table (groups in order of their first
    row): the fewest that hold at least `min_rows` rows and `min_groups` groups (all rows when the
    table has no more)."""
    groups = np.asarray(groups)
    uniq, first, size = np.unique(groups, return_index=True, return_counts=True)
    order = np.argsort(first, kind="stable")
    uniq, size = uniq[order], size[order]
    m = uniq.size
    for k in range(min(max(min_groups, 1), m), m + 1):
        pick = np.unique(np.linspace(0, m - 1, k).astype(int))  # single rows: the screen's subset as it always was
        if size[pick].sum() >= min_rows and pick.size >= min(min_groups, m):
            return np.flatnonzero(np.isin(groups, uniq[pick]))
    return np.arange(groups.size)
