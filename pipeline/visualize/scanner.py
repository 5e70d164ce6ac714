"""Rerun view of the laser-stripe scanner (seed 001), rerun-sdk 0.41.

``log_system(rec, model, table, x_before, x_after, stripes=None)`` logs, in the robot base
frame {B} (``world``):

- ``world/scanner/corners`` the target corners (drawing coordinates);
- ``world/scanner/reconstructed/before`` and ``.../after`` the stripe points reconstructed by
  eq. 13 with the parameters before (nominal / start) and after calibration, and
  ``world/scanner/error/after_x100`` the after-calibration errors ×100;
- ``world/scanner/stripe`` the whole stripe profile reconstructed in 3-D (after), when
  `stripes` = [(joint_positions (5,), stripe_px (S,2)), ...] is given (see `stripes_of`);
- ``image/stripe`` and ``image/corners``: the stripe profile and the picked corner pixels in
  the 640×480 image, one observation per step of the ``time`` timeline.
`rec` may be a `rr.RecordingStream` or a path (an .rrd file is written).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr

TIMELINE = "time"
BEFORE_RGB, AFTER_RGB, CORNER_RGB, STRIPE_RGB = (220, 80, 60), (40, 160, 90), (250, 200, 0), (255, 40, 40)


def stripes_of(recording) -> list[tuple[np.ndarray, np.ndarray]]:
    """(joint_positions, stripe_px) of every `/scanner/stripe` record of a `Recording`."""
    from pipeline.systems.scorbot_scanner import MEASUREMENT_CHANNEL
    return [(np.asarray(m["joint_positions"], float), np.asarray(m.get("stripe_px") or np.zeros((0, 2)), float))
            for m in recording.messages.get(MEASUREMENT_CHANNEL, [])]


def log_system(rec, model, table: dict, x_before: np.ndarray, x_after: np.ndarray,
               stripes: list[tuple[np.ndarray, np.ndarray]] | None = None, artefacts=None) -> None:
    """Scanner scene (see module docstring)."""
    path = None
    if not isinstance(rec, rr.RecordingStream):
        path = Path(rec)
        rec = rr.RecordingStream("robocal", recording_id=f"robocal-scanner-{path.stem}", send_properties=False)
    if stripes is None and artefacts is not None:  # a pipeline run: the stripes are in its recording
        src = Path(str(artefacts.source.get("path") or ""))
        if src.is_file():
            from pipeline.recording.reader import read_recording

            stripes = stripes_of(read_recording(src, topics={"/scanner/stripe"}))
    corners = np.asarray(table["corner"], float)
    before, _ = model.points(x_before, table)
    after, _ = model.points(x_after, table)
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    rec.log("world/scanner/corners", rr.Points3D(corners, colors=[CORNER_RGB], radii=[0.002]), static=True)
    rec.log("world/scanner/reconstructed/before", rr.Points3D(before, colors=[BEFORE_RGB], radii=[0.0015]), static=True)
    rec.log("world/scanner/reconstructed/after", rr.Points3D(after, colors=[AFTER_RGB], radii=[0.0015]), static=True)
    rec.log("world/scanner/error/after_x100", rr.Arrows3D(origins=corners, vectors=100 * (after - corners),
                                                          colors=[AFTER_RGB], radii=[0.0005]), static=True)
    w, h = getattr(model, "image_size", (640, 480))
    pose = np.asarray(table.get("pose", np.zeros(len(corners), int)))
    t_ns = np.asarray(table.get("timestamp_ns", np.arange(len(corners))), np.int64)
    for k, i in enumerate(np.unique(pose)):
        rows = np.flatnonzero(pose == i)
        rec.set_time(TIMELINE, timestamp=np.datetime64(int(t_ns[rows[0]]), "ns"))
        rec.log("image/corners", rr.Points2D(np.asarray(table["pixel"])[rows], colors=[CORNER_RGB], radii=[3.0]))
        rec.log("image/frame", rr.LineStrips2D([[[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1], [0, 0]]]))
        if stripes is not None and k < len(stripes) and len(stripes[k][1]):
            q, spx = stripes[k]
            rec.log("image/stripe", rr.LineStrips2D([spx], colors=[STRIPE_RGB]))
            sub = {"pixel": spx, "joint_positions": np.repeat(q[None], len(spx), 0), "corner": np.zeros((len(spx), 3))}
            rec.log("world/scanner/stripe", rr.LineStrips3D([model.points(x_after, sub)[0]], colors=[STRIPE_RGB],
                                                            radii=[0.0007]))
    rec.reset_time()
    log_camera(rec, model, table, x_after)
    if path is not None:
        rec.save(path)


def camera_poses(model, x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The calibrated camera frame {C} in the base frame at joint readings q (N, 5): rotations
    (N, 3, 3) and origins (N, 3), m — flange pose (eq. 8) · hand-eye transform (eqs. 9–10)."""
    from pipeline.models import camera as cam

    x = np.asarray(x, float)
    s = x[:cam.N_SCANNER]
    Rf, pf = model.flange(x, np.atleast_2d(q))
    R_he = cam.hand_eye_rotation(s[cam.I_W], s[cam.I_PHI], s[cam.I_PSI])
    return Rf @ R_he, pf + np.einsum("nij,j->ni", Rf, s[cam.I_TX:cam.I_TZ + 1])


def log_camera(rec, model, table: dict, x_after: np.ndarray) -> None:
    """``world/scanner/camera``: the calibrated camera at each measurement pose on ``time``, with its
    frustum (a pinhole of the calibrated focal length and the 640×480 image; {C}'s x runs down the
    image rows V, y along the columns U, z forward: rerun's DRF)."""
    from pipeline.models import camera as cam

    if not hasattr(model, "flange"):
        return
    pose = np.asarray(table.get("pose", np.zeros(len(table["joint_positions"]), int)))
    first = np.array([np.flatnonzero(pose == i)[0] for i in np.unique(pose)])
    q = np.asarray(table["joint_positions"], float)[first]
    t_ns = np.asarray(table.get("timestamp_ns", np.arange(len(pose))), np.int64)[first]
    R, p = camera_poses(model, x_after, q)
    s = np.asarray(x_after, float)[:cam.N_SCANNER]
    w, h = getattr(model, "image_size", (640, 480))
    rec.log("world/scanner/camera", rr.Pinhole(focal_length=[float(s[cam.I_F] / s[cam.I_SU]), float(s[cam.I_F] / s[cam.I_SV])],
                                               principal_point=[float(s[cam.I_U0]), float(s[cam.I_V0])],
                                               width=w, height=h, camera_xyz=rr.ViewCoordinates.DRF,
                                               image_plane_distance=0.05), static=True)
    rec.send_columns("world/scanner/camera",
                     indexes=[rr.TimeColumn(TIMELINE, timestamp=t_ns.astype("datetime64[ns]"))],
                     columns=rr.Transform3D.columns(translation=p, mat3x3=R))

