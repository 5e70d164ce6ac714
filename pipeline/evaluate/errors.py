"""The error of a calibrated model on measurements it was not fitted to (pure numpy).

Per measurement type, the error of each row and what it means:

* ``point``: predicted − measured position (n, 3) m, in the instrument frame;
* ``pose``: predicted − measured position (m) and the rotation error ``log(R_pred R_measᵀ)`` (rad),
  (n, 6) — unlike the fit's residual, the rotation part is in radians, not scaled by σ;
* ``plane``: signed distance of the tool point from its plane along the normal (n, 1) m;
* ``coincidence``: the tool point (ball centre) minus the mean of its group's tool points (the
  socket's own estimate from these rows: no fitted point is carried over), (n, 3) m; each known
  distance row: distance between the two groups' means − the known distance (first component);
* ``camera``: each board corner projected through the robot's pose at its image, the calibrated
  hand-eye, board pose and intrinsics — nothing refitted per image — minus where it was detected,
  (n, 2) **px** (u right, v down); a row's group is its image.

The norm of a row is the 3-D norm of its position part (points, poses, coincidences), the 2-D
reprojection error (camera corners, px) or the absolute distance (planes, distance rows).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.identify.model import Table


@dataclass(frozen=True)
class RowErrors:
    """Errors of one recording's rows (see module docstring); `kind` 0 measurement, 1 distance row."""

    error: np.ndarray  # (n, k) m (pose: last three rad)
    norm: np.ndarray  # (n,) m
    label: np.ndarray  # (n,) object: the row's group (target, plane, socket, "distance a–b")
    kind: np.ndarray  # (n,) int


def coincidence_errors(model, x: np.ndarray, data: Table) -> RowErrors:
    """Spread of the tool points about their group mean, and the known distances' errors."""
    kind = np.asarray(data.get("kind", np.zeros(len(data["group"]), int)), int)
    g = np.asarray(data["group"], int)
    touch = kind == 0
    p, *_ = model.tool(x, np.asarray(data["joint_positions"], float), jac=False)
    ng = int(g.max()) + 1 if g.size else 0
    cnt = np.bincount(g[touch], minlength=ng).astype(float)
    mean = np.stack([np.bincount(g[touch], weights=p[touch, a], minlength=ng) for a in range(3)], 1)
    mean = mean / np.maximum(cnt, 1)[:, None]
    e = np.zeros((g.size, 3))
    e[touch] = p[touch] - mean[g[touch]]
    names = list(getattr(model, "groups_", ()))
    name = lambda i: names[i] if i < len(names) else str(i)  # noqa: E731
    label = np.array([name(i) for i in g], object)
    dist = ~touch
    if dist.any():
        gb = np.asarray(data["group_b"], int)
        d = np.linalg.norm(mean[g[dist]] - mean[gb[dist]], axis=1) - np.asarray(data["distance"], float)[dist]
        e[dist, 0] = d
        label[dist] = [f"distance {name(a)}–{name(b)}" for a, b in zip(g[dist], gb[dist])]
    norm = np.where(touch, np.linalg.norm(e, axis=1), np.abs(e[:, 0]))
    return RowErrors(e, norm, label, kind)


def row_errors(model, x: np.ndarray, data: Table, measure: str) -> RowErrors:
    """The errors of every row of `data` under parameters `x` of `model` (module docstring)."""
    n = len(data["joint_positions"])
    if measure == "coincidence":
        return coincidence_errors(model, x, data)
    r = np.asarray(model.residuals(x, data), float).reshape(n, -1)
    label = np.asarray(data.get("label", np.full(n, measure, object)), object)
    if measure == "pose":
        r = r.copy()
        r[:, 3:] /= model.weight  # back to radians
        return RowErrors(r, np.linalg.norm(r[:, :3], axis=1), label, np.zeros(n, int))
    if measure == "plane":
        return RowErrors(r, np.abs(r[:, 0]), label, np.zeros(n, int))
    if measure == "camera":
        return RowErrors(r, np.linalg.norm(r, axis=1), label, np.zeros(n, int))
    return RowErrors(r, np.linalg.norm(r[:, :3], axis=1), label, np.zeros(n, int))


def _figures(e: np.ndarray, norm: np.ndarray, measure: str) -> dict:
    if norm.size == 0:
        return {"n": 0}
    out: dict = {"n": int(norm.size)}
    if measure == "plane":
        out |= {"rms_normal_m": float(np.sqrt(np.mean(norm**2))), "mean_abs_normal_m": float(norm.mean()),
                "max_abs_normal_m": float(norm.max())}
        return out
    if measure == "camera":  # px: the 2-D reprojection error (OpenCV's RMS), per axis under its own name
        return out | {"rms_2d_px": float(np.sqrt(np.mean(norm**2))), "mean_2d_px": float(norm.mean()),
                      "max_2d_px": float(norm.max()), "rms_axis_px": float(np.sqrt(np.mean(e[:, :2] ** 2))),
                      "rms_uv_px": [float(v) for v in np.sqrt(np.mean(e[:, :2] ** 2, axis=0))]}
    p = e[:, :3]
    out |= {"rms_3d_m": float(np.sqrt(np.mean(norm**2))), "mean_3d_m": float(norm.mean()),
            "max_3d_m": float(norm.max()), "rms_axis_m": float(np.sqrt(np.mean(p**2))),
            "rms_xyz_m": [float(v) for v in np.sqrt(np.mean(p**2, axis=0))]}
    if measure == "pose":
        ang = np.linalg.norm(e[:, 3:6], axis=1)
        out |= {"rms_rotation_rad": float(np.sqrt(np.mean(ang**2))), "max_rotation_rad": float(ang.max())}
    return out


def by_label(errs: RowErrors, labels: np.ndarray, order: tuple[str, ...], measure: str) -> dict:
    """Figures of the measurement rows of each label in `order` (`labels`: one per row of `errs`) that has rows."""
    m = errs.kind == 0
    return {g: _figures(errs.error[m & (labels == g)], errs.norm[m & (labels == g)], measure)
            for g in order if np.any(m & (labels == g))}


def summarise(errs: RowErrors, measure: str) -> dict:
    """Figures of one recording (SI; a camera's in px): the headline over every measurement row, the same
    per group, and for coincidences the known distances' errors."""
    m = errs.kind == 0
    doc = _figures(errs.error[m], errs.norm[m], measure)
    groups = {}
    for g in dict.fromkeys(errs.label[m]):
        s = m & (errs.label == g)
        groups[str(g)] = _figures(errs.error[s], errs.norm[s], measure)
    doc["groups"] = groups
    d = ~m
    if d.any():
        doc["distances"] = {str(lab): float(v) for lab, v in zip(errs.label[d], errs.error[d, 0])}
        doc["rms_distance_error_m"] = float(np.sqrt(np.mean(errs.error[d, 0] ** 2)))
        doc["max_abs_distance_error_m"] = float(np.max(np.abs(errs.error[d, 0])))
    return doc
