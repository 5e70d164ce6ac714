"""A folder of calibration-board images plus the robot's state at each → a self-contained recording
(`robocal import images`).

The robot's state at an image is either its joint positions or its measured flange pose, read by
`pipeline.importers.pose_files` (CSV tables, or one 4×4 base→flange matrix per line as hand-eye
datasets ship them).  A pose becomes the joint positions of a six-joint "pose chain" URDF
(prismatic x, y, z, then revolute yaw about z, pitch about y, roll about x — the URDF rpy
convention), whose kinematics are known: only the camera, hand-eye and board are fitted.

An image is matched to its row by file name or stem, or to its matrix line by the number its name ends in.  Each image with the target found becomes
one ``/measure/camera`` message (corner ids, pixels); every image not used is listed in the
campaign (``camera.skipped``: image and reason).  With `keep_images` each used image file is also
stored in the recording as an MCAP attachment (its bytes unchanged).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.camera.detect import Detection
from pipeline.camera.targets import Target
from pipeline.errors import RobocalError
from pipeline.importers.pose_files import States
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


def select(files: list[Path], only: str = "", exclude: str = "") -> list[Path]:
    """The image files `only` names (all when empty) less those `exclude` names: comma-separated file
    names, stems or shell patterns (``im_05,im_1*``); a name or pattern that matches no image is refused
    (a typo would otherwise silently change the split)."""
    from fnmatch import fnmatchcase

    def hits(spec: str, option: str) -> set[Path]:
        out: set[Path] = set()
        for pat in (s.strip() for s in spec.split(",")):
            if not pat:
                continue
            m = {f for f in files if fnmatchcase(f.name, pat) or fnmatchcase(f.stem, pat)}
            if not m:
                names = ", ".join(f.name for f in files[:6]) + (" …" if len(files) > 6 else "")
                raise RobocalError(f"{option} {pat!r}: no image of the folder is called so (have: {names})")
            out |= m
        return out

    keep = hits(only, "--only") if only.strip() else set(files)
    keep -= hits(exclude, "--exclude")
    return [f for f in files if f in keep]


def match(detections: list[Detection], states: States, folder_names: list[str] | None = None) -> list[Detection]:
    """Attach each image's state (`States.lookup`, numbered from all the folder's image names where given);
    an image without one is listed as such."""
    states.bind(folder_names if folder_names is not None else [d.name for d in detections])
    for d in detections:
        q = states.lookup(d.name)
        if q is None and d.used:
            d.status, d.reason = "no state", states.missing(d.name)
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
