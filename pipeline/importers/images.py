"""A folder of calibration-board images plus the robot's state at each → a self-contained recording
(`robocal import images`).

The robot's state at an image is either its joint positions (a CSV with an ``image`` column and
one column per joint of the URDF chain, matched by name) or its measured flange pose (a CSV with
``image, x, y, z`` in m and ``qx, qy, qz, qw`` or ``roll, pitch, yaw`` in rad: the flange in the
robot base frame).  A pose becomes the joint positions of a six-joint "pose chain" URDF
(prismatic x, y, z, then revolute yaw about z, pitch about y, roll about x — the URDF rpy
convention), whose kinematics are known: only the camera, hand-eye and board are fitted.

An image is matched to its row by file name or stem.  Each image with the target found becomes
one ``/measure/camera`` message (corner ids, pixels); every image not used is listed in the
campaign (``camera.skipped``: image and reason).  With `keep_images` each used image file is also
stored in the recording as an MCAP attachment (its bytes unchanged).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
from scipy.spatial.transform import Rotation

from pipeline.camera.detect import Detection
from pipeline.camera.targets import Target
from pipeline.errors import RobocalError
from pipeline.importers.bounds import check_bound
from pipeline.importers.recording import T0_NS
from pipeline.models.urdf import RobotDescription, parse
from pipeline.recording.schemas import META_CAMPAIGN, META_URDF
from pipeline.recording.writer import RecordingWriter

POSE_JOINTS = ("x", "y", "z", "yaw", "pitch", "roll")
MEDIA = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".bmp": "image/bmp",
         ".tif": "image/tiff", ".tiff": "image/tiff"}


def pose_chain() -> RobotDescription:
    """The six-joint chain whose joint positions (x, y, z, yaw, pitch, roll) are a measured flange pose."""
    axes = {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1", "yaw": "0 0 1", "pitch": "0 1 0", "roll": "1 0 0"}
    links = ["base", "px", "py", "pz", "ryaw", "rpitch", "flange"]
    joints = []
    for i, j in enumerate(POSE_JOINTS):
        kind = "prismatic" if i < 3 else "revolute"
        lim = 'lower="-100" upper="100"' if i < 3 else 'lower="-7" upper="7"'
        joints.append(f'<joint name="{j}" type="{kind}"><parent link="{links[i]}"/><child link="{links[i + 1]}"/>'
                      f'<origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="{axes[j]}"/>'
                      f'<limit {lim} effort="0" velocity="1"/></joint>')
    text = ('<?xml version="1.0"?>\n<robot name="measured_flange_pose">'
            + "".join(f'<link name="{n}"/>' for n in links) + "".join(joints) + "</robot>\n")
    return parse(text, "base", "flange", source="robocal pose chain")


def _read_csv(path: Path) -> dict[str, np.ndarray]:
    try:
        t = pacsv.read_csv(path, convert_options=pacsv.ConvertOptions(column_types={"image": pa.string()}))
    except (pa.ArrowInvalid, OSError) as e:
        raise RobocalError(f"{path}: cannot read CSV ({str(e).splitlines()[0]})") from None
    if "image" not in t.column_names:
        raise RobocalError(f"{path}: no 'image' column (the image file name of each row)")
    return {n: np.asarray(t.column(n).to_pylist(), object) for n in t.column_names}


def _numbers(path: Path, cols: dict, names: list[str]) -> np.ndarray:
    missing = [c for c in names if c not in cols]
    if missing:
        raise RobocalError(f"{path}: column(s) {', '.join(missing)} missing (have: {', '.join(cols)})")
    out = np.empty((len(cols["image"]), len(names)))
    for j, c in enumerate(names):
        for i, v in enumerate(cols[c]):
            try:
                out[i, j] = float(v)
            except (TypeError, ValueError):
                raise RobocalError(f"{path}: row {i + 2}: column {c!r}: {v!r} is not a number") from None
            if not np.isfinite(out[i, j]):
                raise RobocalError(f"{path}: row {i + 2}: column {c!r} is empty, NaN or inf")
        check_bound(path, c, out[:, j])  # the bound every importer shares (importers.bounds)
    return out


def read_poses(path: Path) -> dict[str, np.ndarray]:
    """Image name → the pose chain's joint positions (x, y, z, yaw, pitch, roll) from a pose CSV."""
    cols = _read_csv(path)
    xyz = _numbers(path, cols, ["x", "y", "z"])
    if all(c in cols for c in ("qx", "qy", "qz", "qw")):
        quat = _numbers(path, cols, ["qx", "qy", "qz", "qw"])
        norm = np.linalg.norm(quat, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1) > 1e-3)
        if bad.size:
            raise RobocalError(f"{path}: row {bad[0] + 2}: qx..qw is not a unit quaternion (norm {norm[bad[0]]:.4g})")
        ypr = Rotation.from_quat(quat / norm[:, None]).as_euler("ZYX")
    else:
        rpy = _numbers(path, cols, ["roll", "pitch", "yaw"])
        ypr = rpy[:, ::-1]
    if np.any(np.abs(xyz) > 100):
        i = int(np.flatnonzero(np.any(np.abs(xyz) > 100, axis=1))[0])
        raise RobocalError(f"{path}: row {i + 2}: position {xyz[i].tolist()} beyond 100 m (mm given as m?)")
    return {str(n): np.r_[xyz[i], ypr[i]] for i, n in enumerate(cols["image"])}


def read_joints(path: Path, desc: RobotDescription, joint_units: str = "rad") -> dict[str, np.ndarray]:
    """Image name → joint positions in the chain's order (rad / m) from a joint CSV."""
    cols = _read_csv(path)
    q = _numbers(path, cols, desc.joint_names)
    if joint_units == "deg":
        rev = [j.type != "prismatic" for j in desc.movable]
        q[:, rev] = np.deg2rad(q[:, rev])
    return {str(n): q[i] for i, n in enumerate(cols["image"])}


def match(detections: list[Detection], states: dict[str, np.ndarray], states_path: Path) -> list[Detection]:
    """Attach each image's row (by file name, else stem); an image without one is listed as such."""
    by_stem = {Path(k).stem: v for k, v in states.items()}
    for d in detections:
        q = states.get(d.name, by_stem.get(Path(d.name).stem))
        if q is None and d.used:
            d.status, d.reason = "no state", f"no row for it in {states_path.name}"
        d.q = q  # type: ignore[attr-defined]
    return detections


def write_camera_recording(out: Path, desc: RobotDescription, target: Target, detections: list[Detection],
                           campaign: dict, folder: Path | None = None, keep_images: bool = False) -> int:
    """Write the used detections (one message each) and the campaign; returns images written."""
    used = [d for d in detections if d.used]
    skipped = [{"image": d.name, "status": d.status, "reason": d.reason} for d in detections if not d.used]
    partial = [{"image": d.name, "reason": d.reason} for d in used if d.status == "partial"]
    camp = {"system": "urdf", "measure": "camera", "joint_names": desc.joint_names, **campaign,
            "target": target.spec, "images": [d.name for d in used], "skipped": skipped, "partial": partial}
    with RecordingWriter(out) as w:
        w.metadata(META_URDF, {"urdf": desc.urdf, "root": desc.root, "tip": desc.tip, "source": desc.source})
        w.metadata(META_CAMPAIGN, camp)
        for i, d in enumerate(used):
            t = getattr(d, "t_ns", None) or T0_NS + i * 1_000_000_000  # a bag's image stamp, else 1 s apart
            w.write("/measure/camera", {"timestamp_ns": t, "joint_positions": np.asarray(d.q, float).tolist(),
                                        "image": d.name, "corners": d.ids.tolist(), "pixels": d.pixels.ravel().tolist(),
                                        "width": d.size[0], "height": d.size[1]})
            if keep_images and folder is not None:
                p = folder / d.name
                w.attachment(d.name, p.read_bytes(), MEDIA.get(p.suffix.lower(), "application/octet-stream"), t)
    return len(used)
