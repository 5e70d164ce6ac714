"""A camera run in rerun: the calibrated camera's frustum at every image, the board's corners in
3-D, and each image with its detected and reprojected corners (rerun-sdk 0.41).

Frames: the run's ``world`` is the chain's instrument frame (the board, eye-in-hand; the camera,
eye-to-hand); ``world/base`` is the robot's base frame placed there by the calibrated ``base.*``
(a Transform3D), and everything below it is in base coordinates, m:

- ``world/base/board/corners`` the board's corners (Points3D, labelled by corner id) — fixed,
  eye-in-hand; eye-to-hand the board moves with the flange: ``world/base/boards/<image>``;
- ``world/base/cameras/<image>`` the calibrated camera pose at that image (Transform3D, OpenCV's
  x right, y down, z forward) with ``rr.Pinhole`` of the calibrated intrinsics (the frustum), and
  in its image plane (px): ``…/image`` the image itself when the recording kept it
  (``--keep-images``; PNG and JPEG as kept, other formats re-encoded as PNG for the viewer), ``…/detected`` and ``…/reprojected`` corners (Points2D) and
  ``…/residuals_x<k>`` lines from each detected corner along its residual, magnified k×
  (k in 1, 10, 100, 1000: the 95th percentile drawn ≈ 10 px long).

Lens distortion is in the reprojected points (`pipeline.camera.projection`); rerun's pinhole
itself is distortion-free, so the frustum is the ideal camera's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr

from pipeline.camera import projection as pj
from pipeline.camera.start import inverse

DETECTED_RGB = (250, 200, 0)
REPROJECTED_RGB = (40, 160, 90)
RESIDUAL_RGB = (214, 39, 40)
BOARD_RGB = (235, 235, 235)


def line_scale(residuals_px: np.ndarray, drawn_px: float = 10.0) -> int:
    """Magnification of residual lines: the largest of 1, 10, 100, 1000 that draws the 95th
    percentile of |residual| at most `drawn_px` long."""
    r = np.linalg.norm(np.asarray(residuals_px, float).reshape(-1, 2), axis=1)
    p = float(np.percentile(r, 95)) if r.size else 0.0
    for k in (1000, 100, 10):
        if k * p <= drawn_px:
            return k
    return 1


def camera_poses(model, x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T_base_camera, T_base_board) (m,4,4) at configurations q (m, n_joints), robot base frame."""
    from pipeline.camera.start import homogeneous
    from pipeline.models import chain as ch
    from pipeline.models.urdf_arm import frame_matrix

    ib = model.parameter_names().index("base.x")
    B = frame_matrix(x[ib:ib + 6])  # instrument ← robot base
    R, p = ch.forward(model.kin.chain(), model.split(x)[0], q)
    T_base_tool = inverse(B) @ homogeneous(R, p)
    fixed = np.broadcast_to(inverse(B), T_base_tool.shape)
    return (T_base_tool, fixed) if model.mount == "tip" else (fixed, T_base_tool)


SHOWN_AS_IS = ("image/png", "image/jpeg")


def for_viewer(data: bytes, media: str) -> tuple[bytes, str]:
    """An image as the viewer decodes it: PNG and JPEG unchanged, any other format OpenCV reads
    (BMP, TIFF, …) re-encoded as PNG (lossless)."""
    if media in SHOWN_AS_IS:
        return data, media
    import cv2

    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"a kept image ({media}) OpenCV cannot decode")
    return cv2.imencode(".png", img)[1].tobytes(), "image/png"


def kept_images(recording: Path | None) -> dict[str, tuple[bytes, str]]:
    """name → (bytes, media type) of the images kept in the recording as MCAP attachments."""
    if recording is None or not Path(recording).is_file():
        return {}
    from mcap.reader import make_reader

    from pipeline.camera.detect import IMAGE_SUFFIXES

    with open(recording, "rb") as f:
        return {a.name: (a.data, a.media_type) for a in make_reader(f).iter_attachments()
                if Path(a.name).suffix.lower() in IMAGE_SUFFIXES}


def log_camera(rec: rr.RecordingStream, model, table: dict, x: np.ndarray, recording: Path | None = None,
               board: np.ndarray | None = None) -> list[str]:
    """Log the entities of the module docstring for the calibrated x; `board` (k,3) m: every
    corner of the target in its frame (default: the corners the images saw); returns the paths."""
    from pipeline.models.urdf_arm import frame_matrix
    from pipeline.visualize.scene import entity_part

    img = np.asarray(table["image"])
    ids, first = np.unique(img, return_index=True)
    q = np.asarray(table["joint_positions"], float)[first]
    T_cam, T_board = camera_poses(model, x, q)
    ib = model.parameter_names().index("base.x")
    Bm = frame_matrix(x[ib:ib + 6])
    rec.log("world/base", rr.Transform3D(translation=Bm[:3, 3], mat3x3=Bm[:3, :3]), static=True)
    paths = ["world/base"]
    k = model.split(x)[1]
    uv, _ = model.predict(x, table)
    px = np.asarray(table["pixel"], float)
    scale = line_scale(uv - px)
    labels = np.asarray(table.get("label", img)).astype(str)
    corner = np.asarray(table["corner"])
    pts = np.asarray(table["point"], float)
    images = kept_images(recording)
    if model.mount == "tip":
        if board is None:  # the corners the images saw, each once
            cid, at = np.unique(corner, return_index=True)
            board = pts[at]
        else:
            cid = np.arange(len(board))
        P = board @ T_board[0, :3, :3].T + T_board[0, :3, 3]
        rec.log("world/base/board/corners", rr.Points3D(P, colors=[BOARD_RGB], radii=[0.003],
                                                        labels=[str(c) for c in cid], show_labels=False), static=True)
        paths.append("world/base/board/corners")
    for j, (i, f) in enumerate(zip(ids, first)):
        m = img == i
        name = entity_part(labels[f])
        base = f"world/base/cameras/{name}"
        T = T_cam[j]
        rec.log(base, rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]), static=True)
        rec.log(base, rr.Pinhole(image_from_camera=pj.camera_matrix(k), resolution=list(model.image_size),
                                 camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=0.05), static=True)
        rec.log(f"{base}/detected", rr.Points2D(px[m], colors=[DETECTED_RGB], radii=[2.0],
                                                labels=[str(c) for c in corner[m]], show_labels=False), static=True)
        rec.log(f"{base}/reprojected", rr.Points2D(uv[m], colors=[REPROJECTED_RGB], radii=[1.5]), static=True)
        rec.log(f"{base}/residuals_x{scale}", rr.LineStrips2D(
            np.stack([px[m], px[m] + scale * (uv[m] - px[m])], axis=1), colors=[RESIDUAL_RGB], radii=[0.6]), static=True)
        paths += [base, f"{base}/detected", f"{base}/reprojected", f"{base}/residuals_x{scale}"]
        if labels[f] in images:
            data, media = for_viewer(*images[labels[f]])
            rec.log(f"{base}/image", rr.EncodedImage(contents=data, media_type=media), static=True)
            paths.append(f"{base}/image")
        if model.mount == "world":
            Tb = T_board[j]
            Pb = pts[m] @ Tb[:3, :3].T + Tb[:3, 3]
            rec.log(f"world/base/boards/{name}", rr.Points3D(Pb, colors=[BOARD_RGB], radii=[0.003]), static=True)
            paths.append(f"world/base/boards/{name}")
    return paths


def log_run(rec: rr.RecordingStream, art, model, table: dict, x: np.ndarray, params: dict,
            warnings: list[str]) -> list[str]:
    """`log_camera` for a run: the board from the recording's campaign, the images from the
    source recording (`params["recording"]` or the run's source); a drawing error becomes a warning."""
    from pipeline.camera.targets import parse
    from pipeline.visualize.source import _recording_path

    try:
        spec = (art.metadata.get("robocal.campaign") or {}).get("target")
        board = parse(spec).points if isinstance(spec, str) else None
        return log_camera(rec, model, table, x, _recording_path(art, params), board)
    except Exception as e:  # a drawing error must not lose the rest of the recording
        warnings.append(f"camera views not logged: {type(e).__name__}: {e}")
        return []
