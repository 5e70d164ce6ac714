"""Camera recordings → the camera measurement model and its table (one row per detected corner).

Read by `pipeline.systems.urdf_robot.load` for campaigns with ``measure: camera``.  The campaign
holds ``target`` (a `pipeline.camera.targets` declaration), ``mount`` (tip | world), ``lens``
(pinhole | fisheye), ``n_dist`` and ``image_size`` [width, height] px, and
``kinematics_known`` (the joint positions are a measured flange pose); optionally
``start_intrinsics`` (fx, fy, cx, cy px, distortion terms: what the camera states, e.g. a ROS
CameraInfo's K and D), the model's nominal intrinsics and the start of OpenCV's calibrateCamera.
"""

from __future__ import annotations

import numpy as np

from pipeline.camera.targets import parse
from pipeline.errors import RobocalError, where
from pipeline.measurements.camera import CameraModel


def camera_model(arm, campaign: dict) -> CameraModel:
    size = campaign.get("image_size") or [640, 480]
    return CameraModel(arm, mount=str(campaign.get("mount", "tip")), lens=str(campaign.get("lens", "pinhole")),
                       n_dist=int(campaign.get("n_dist", 5)), image_size=(int(size[0]), int(size[1])),
                       kinematics_known=bool(campaign.get("kinematics_known", False)),
                       k_start=tuple(float(v) for v in campaign["start_intrinsics"]) if campaign.get("start_intrinsics")
                       else None)


def camera_table(rec, topic: str, msgs: list[dict], arm, campaign: dict) -> dict[str, np.ndarray]:
    """Flatten the per-image messages into per-corner rows (see `pipeline.measurements.camera`)."""
    try:
        target = parse(str(campaign.get("target", "")))
    except RobocalError as e:
        raise RobocalError(f"{rec.path}: metadata robocal.campaign: {e}") from None
    pts = target.points
    cols = {k: [] for k in ("timestamp_ns", "joint_positions", "image", "corner", "pixel", "label")}
    for i, m in enumerate(msgs):
        try:
            q = np.asarray(m["joint_positions"], float)
            ids = np.asarray(m["corners"], np.int64).reshape(-1)
            px = np.asarray(m["pixels"], float)
            if px.ndim != 1 or px.size != 2 * ids.size:
                raise ValueError(f"pixels holds {px.size} numbers for {ids.size} corners (u, v each)")
            px = px.reshape(-1, 2)
        except (KeyError, TypeError, ValueError) as e:
            raise RobocalError(f"{where(rec.path, topic, i)}: {e.__class__.__name__}: {e}") from None
        if q.shape != (arm.n_joints,):
            raise RobocalError(f"{where(rec.path, topic, i)}: joint_positions has {q.size} values, "
                               f"the chain {arm.n_joints}")
        if not np.all(np.isfinite(px)) or not np.all(np.isfinite(q)):
            raise RobocalError(f"{where(rec.path, topic, i)}: pixels or joint_positions hold NaN or inf")
        if ids.size and (ids.min() < 0 or ids.max() >= len(pts)):
            raise RobocalError(f"{where(rec.path, topic, i)}: corner id {int(ids.max())} is not on the target "
                               f"{target.spec} ({len(pts)} corners)")
        n = len(ids)
        cols["timestamp_ns"].append(np.full(n, int(m.get("timestamp_ns", 0)), np.int64))
        cols["joint_positions"].append(np.repeat(q[None], n, 0))
        cols["image"].append(np.full(n, i, np.int64))
        cols["corner"].append(ids)
        cols["pixel"].append(px)
        cols["label"].append(np.full(n, str(m.get("image", f"image {i}")), object))
    if not msgs:
        raise RobocalError(f"{rec.path}: {topic} has no images")
    t = {k: np.concatenate(v) for k, v in cols.items()}
    t["point"] = pts[t["corner"]]
    t["record"] = np.arange(len(t["corner"]))
    return t
