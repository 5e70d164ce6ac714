"""Rerun view of the Delta + laser-tracker system (seed 003), rerun-sdk 0.41.

``log_system(rec, model, table, x_before, x_after)`` logs, in the tracker frame {T} (the
``world`` of the run; each parameter vector carries its own registration {T}→{A}):

- ``world/delta/base`` the fixed platform (actuator joints) and ``world/delta/robot`` the
  calibrated robot (upper arms, parallelogram rods as their centre lines, moving platform) at
  every measurement, on the ``time`` timeline (static: the first pose);
- ``world/delta/measured`` the tracker's reflector positions;
- ``world/delta/predicted/before`` and ``.../after`` the reflector predicted by the nominal and
  the calibrated model; ``world/delta/error/before`` (true scale) and ``.../after_x100`` (×100)
  the vectors from measured to predicted.
"""

from __future__ import annotations

import numpy as np
import rerun as rr

from pipeline.models import delta as dm
from pipeline.measurements.registration import registration_matrix

TIMELINE = "time"
NOMINAL_RGB = (220, 80, 60)
CALIBRATED_RGB = (40, 160, 90)
MEASURED_RGB = (250, 200, 0)
ROBOT_RGB = (90, 110, 150)
AFTER_SCALE = 100.0


def to_tracker(model, x: np.ndarray, p_a: np.ndarray) -> np.ndarray:
    """Base-frame points (..., 3) m to the tracker frame with x's registration."""
    R, t = registration_matrix(np.asarray(x)[model.n_beta: model.n_beta + 6])
    return (np.asarray(p_a) - t) @ R


def robot_strips(model, x: np.ndarray, theta: np.ndarray) -> list[np.ndarray]:
    """Line strips of the robot (simplified-model geometry) at actuator angles theta (N, 3), in
    {T}: per pose, the base triangle, three legs (base joint → elbow → platform joint) and the
    platform triangle.  Returns a flat list of (k, 3) arrays, 5 per pose."""
    beta = dm.split(np.asarray(x)[: model.n_beta], model.extended)[0].ravel()
    theta = np.atleast_2d(theta)
    p, _ = dm.forward(model.delta, beta, theta)
    g = dm.geometry(model.delta, beta, theta, p)
    base, elbow, plat = (to_tracker(model, x, g[k]) for k in ("base", "elbow", "platform"))
    strips: list[np.ndarray] = []
    for i in range(theta.shape[0]):
        strips.append(np.vstack([base[i], base[i][:1]]))
        strips += [np.stack([base[i, leg], elbow[i, leg], plat[i, leg]]) for leg in range(3)]
        strips.append(np.vstack([plat[i], plat[i][:1]]))
    return strips


def log_system(rec: rr.RecordingStream, model, table: dict, x_before: np.ndarray, x_after: np.ndarray,
               artefacts=None) -> None:
    """Delta scene (see module docstring)."""
    theta = np.asarray(table["joint_positions"], float)
    measured = np.asarray(table["point"], float)
    pred = {}
    for name, x in (("before", x_before), ("after", x_after)):
        pred[name] = to_tracker(model, x, model.reflector(x, theta))
    rec.log("world/delta/measured", rr.Points3D(measured, colors=[MEASURED_RGB], radii=[0.003]), static=True)
    rec.log("world/delta/predicted/before", rr.Points3D(pred["before"], colors=[NOMINAL_RGB], radii=[0.002]),
            static=True)
    rec.log("world/delta/predicted/after", rr.Points3D(pred["after"], colors=[CALIBRATED_RGB], radii=[0.002]),
            static=True)
    rec.log("world/delta/error/before", rr.Arrows3D(origins=measured, vectors=pred["before"] - measured,
                                                    colors=[NOMINAL_RGB], radii=[0.0008]), static=True)
    rec.log("world/delta/error/after_x100", rr.Arrows3D(origins=measured,
                                                        vectors=AFTER_SCALE * (pred["after"] - measured),
                                                        colors=[CALIBRATED_RGB], radii=[0.0008]), static=True)
    strips = robot_strips(model, x_after, theta)
    rec.log("world/delta/base", rr.LineStrips3D([strips[0]], colors=[ROBOT_RGB], radii=[0.004]), static=True)
    rec.log("world/delta/robot", rr.LineStrips3D(strips[1:5], colors=[ROBOT_RGB], radii=[0.003]), static=True)
    t_ns = table.get("timestamp_ns")
    if t_ns is None:
        return
    for i, t in enumerate(np.asarray(t_ns, np.int64)):
        rec.set_time(TIMELINE, timestamp=np.datetime64(int(t), "ns"))
        rec.log("world/delta/robot", rr.LineStrips3D(strips[5 * i + 1: 5 * i + 5], colors=[ROBOT_RGB], radii=[0.003]))
    rec.reset_time()
