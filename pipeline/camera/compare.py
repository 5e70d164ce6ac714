"""Held-out comparison of camera + hand-eye calibrations: robocal's joint fit against OpenCV's
calibrateCamera followed by each calibrateHandEye method and calibrateRobotWorldHandEye, on the
same detections and the same split of images.

For a calibration (intrinsics k, X, Y as `pipeline.camera.start.hand_eye`) and an image never
used to fit it:

* **reprojection**: the board's corners predicted through the robot's pose at the image,
  projected, minus the detected corners (px): the RMS over corners of the 2-D error (OpenCV's
  reprojection RMS, ``reprojection_rms_2d_px``) and over the u, v components (``reprojection_rms_px``,
  = 2-D/√2 when isotropic);
* **board in base**: the board's centre located from the image alone (solvePnP with the
  calibration's intrinsics) and carried into the robot base frame by the robot's pose and the
  hand-eye transform, minus the calibration's board position (eye-in-hand: Y; mm).
"""

from __future__ import annotations

import numpy as np

from pipeline.camera import projection as pj
from pipeline.camera.start import (HAND_EYE_METHODS, calibrate_camera, flange_poses, hand_eye, homogeneous, inverse,
                                   robot_world_hand_eye, views)
from pipeline.identify.model import Table, take


def frames_of(model, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(k, X, Y) of a robocal parameter vector (X, Y as `hand_eye`)."""
    from pipeline.models.urdf_arm import frame_matrix

    names = model.parameter_names()
    ib, it = names.index("base.x"), names.index("tool.x")
    base, tool = frame_matrix(x[ib:ib + 6]), frame_matrix(x[it:it + 6])
    if model.mount == "tip":
        return x[model.n_kin:], tool, inverse(base)
    return x[model.n_kin:], inverse(base), tool


def held_out(model, x: np.ndarray, k: np.ndarray, X: np.ndarray, Y: np.ndarray, test: Table) -> dict:
    """Held-out figures of one calibration on the images of `test` (module docstring)."""
    import cv2

    ids, obj, px, q = views(test)
    T_bf = flange_poses(model, x, q)
    res, dist = [], []
    for i in range(len(ids)):
        T_cb = inverse(X) @ inverse(T_bf[i]) @ Y if model.mount == "tip" else inverse(X) @ T_bf[i] @ Y
        pc = obj[i] @ T_cb[:3, :3].T + T_cb[:3, 3]
        res.append(pj.project(k, pc, model.lens) - px[i])
        if model.lens == pj.FISHEYE:
            und = cv2.fisheye.undistortPoints(px[i][:, None, :], pj.camera_matrix(k), k[4:])
            ok, rv, tv = cv2.solvePnP(obj[i], und, np.eye(3), None)
        else:
            ok, rv, tv = cv2.solvePnP(obj[i], px[i], pj.camera_matrix(k), k[4:])
        T_pnp = homogeneous(cv2.Rodrigues(rv)[0], tv.ravel())
        c = np.r_[obj[i].mean(0), 1.0]
        if model.mount == "tip":
            seen, known = T_bf[i] @ X @ T_pnp @ c, Y @ c
        else:  # the board on the flange: its centre in base seen by the fixed camera vs carried by the robot
            seen, known = X @ T_pnp @ c, T_bf[i] @ Y @ c
        dist.append(np.linalg.norm(seen[:3] - known[:3]))
    r = np.concatenate(res)
    return {"reprojection_rms_2d_px": float(np.sqrt(np.mean(np.sum(r**2, axis=1)))),
            "reprojection_rms_px": float(np.sqrt(np.mean(r**2))), "board_rms_mm": float(np.sqrt(np.mean(np.square(dist)))) * 1e3,
            "residuals": r, "board_mm": np.asarray(dist) * 1e3}


def opencv_methods(model, train: Table, n_dist: int) -> dict[str, tuple]:
    """(k, X, Y) of OpenCV's calibrateCamera + each hand-eye method on `train`."""
    _, obj, px, q = views(train)
    k, T_cb, _ = calibrate_camera(obj, px, tuple(model.image_size), model.lens, n_dist)
    T_bf = flange_poses(model, model.nominal(), q)
    out = {m: (k, *hand_eye(T_bf, T_cb, model.mount, m)) for m in HAND_EYE_METHODS}
    for m in ("SHAH", "LI"):
        out[f"RWHE_{m}"] = (k, *robot_world_hand_eye(T_bf, T_cb, model.mount, m))
    return out


def image_splits(n_images: int, k: int, repeats: int, seed: int = 0) -> list[np.ndarray]:
    """Held-out image sets: `repeats` seeded k-fold partitions of the images."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(repeats):
        perm = rng.permutation(n_images)
        out += [np.sort(perm[i::k]) for i in range(k)]
    return out


def split_rows(data: Table, test_images: np.ndarray) -> tuple[dict, dict]:
    img = np.asarray(data["image"])
    ids = np.unique(img)
    mask = np.isin(img, ids[test_images])
    return take(data, ~mask), take(data, mask)
