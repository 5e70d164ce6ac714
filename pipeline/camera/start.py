"""OpenCV's two-step camera + hand-eye calibration, as the start of robocal's joint fit and as
the reference it is compared with (`benchmarks/bench_handeye.py`).

Frames: ``T_a_b`` maps b coordinates into a (4×4, m).  Eye-in-hand: camera on the flange,
board fixed in the robot base frame; eye-to-hand: camera fixed, board on the flange.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.camera import projection as pj
from pipeline.identify.model import Table
from pipeline.models import chain as ch

HAND_EYE_METHODS = ("TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS")


def homogeneous(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(…,4,4) from rotations (…,3,3) and translations (…,3)."""
    T = np.zeros(R.shape[:-2] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def inverse(T: np.ndarray) -> np.ndarray:
    R = np.swapaxes(T[..., :3, :3], -1, -2)
    return homogeneous(R, -np.einsum("...ij,...j->...i", R, T[..., :3, 3]))


def mean_pose(T: np.ndarray) -> np.ndarray:
    """Mean of poses (N,4,4): chordal rotation mean, mean translation."""
    return homogeneous(Rotation.from_matrix(T[:, :3, :3]).mean().as_matrix(), T[:, :3, 3].mean(0))


def views(data: Table) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray], np.ndarray]:
    """Per image (sorted ids): image ids (m,), board points [(k,3)], pixels [(k,2)] and joint positions (m, nj)."""
    img = np.asarray(data["image"])
    ids, first = np.unique(img, return_index=True)
    P, uv = np.asarray(data["point"], float), np.asarray(data["pixel"], float)
    return (ids, [P[img == i] for i in ids], [uv[img == i] for i in ids],
            np.asarray(data["joint_positions"], float)[first])


def calibrate_camera(obj: list[np.ndarray], px: list[np.ndarray], size: tuple[int, int], lens: str, n_dist: int,
                     k0: np.ndarray | None = None):
    """OpenCV's intrinsics (k vector as `projection`) and each view's board pose in the camera,
    T_cam_board (m,4,4); rms reprojection px.  `k0`: intrinsics to start from (pinhole)."""
    import cv2

    o = [np.asarray(a, np.float32) for a in obj]
    p = [np.asarray(a, np.float32) for a in px]
    if lens == pj.FISHEYE:
        flags = cv2.fisheye.CALIB_RECOMPUTE_EXTRINSIC | cv2.fisheye.CALIB_FIX_SKEW
        K0 = np.array([[size[0], 0, size[0] / 2], [0, size[0], size[1] / 2], [0, 0, 1]], float)
        rms, K, d, rv, tv = cv2.fisheye.calibrate([a[:, None, :].astype(np.float64) for a in o],
                                                  [a[:, None, :].astype(np.float64) for a in p], size, K0,
                                                  np.zeros(4), flags=flags | cv2.fisheye.CALIB_USE_INTRINSIC_GUESS)
    else:
        flags = {4: cv2.CALIB_FIX_K3, 5: 0, 8: cv2.CALIB_RATIONAL_MODEL}[n_dist]
        if k0 is None:
            rms, K, d, rv, tv = cv2.calibrateCamera(o, p, size, None, None, flags=flags)
        else:
            d0 = np.zeros(8)
            d0[:min(n_dist, len(k0) - 4)] = np.asarray(k0, float)[4:4 + n_dist]
            rms, K, d, rv, tv = cv2.calibrateCamera(o, p, size, pj.camera_matrix(k0), d0[:max(n_dist, 5)],
                                                    flags=flags | cv2.CALIB_USE_INTRINSIC_GUESS)
    k = np.r_[K[0, 0], K[1, 1], K[0, 2], K[1, 2], np.asarray(d, float).ravel()[:n_dist]]
    R = np.stack([cv2.Rodrigues(np.asarray(r, float))[0] for r in rv])
    return k, homogeneous(R, np.asarray(tv, float).reshape(-1, 3)), float(rms)


def hand_eye(T_base_flange: np.ndarray, T_cam_board: np.ndarray, mount: str, method: str = "PARK"):
    """OpenCV's calibrateHandEye: (X, Y) with X = T_flange_cam and Y = T_base_board (eye-in-hand)
    or X = T_base_cam and Y = T_flange_board (eye-to-hand); Y is the mean over the views."""
    import cv2

    robot = T_base_flange if mount == "tip" else inverse(T_base_flange)
    R, t = cv2.calibrateHandEye(list(robot[:, :3, :3]), list(robot[:, :3, 3]), list(T_cam_board[:, :3, :3]),
                                list(T_cam_board[:, :3, 3]), method=getattr(cv2, f"CALIB_HAND_EYE_{method}"))
    X = homogeneous(R, t.ravel())
    Y = mean_pose(robot @ X @ T_cam_board)
    return X, Y


def robot_world_hand_eye(T_base_flange: np.ndarray, T_cam_board: np.ndarray, mount: str, method: str = "SHAH"):
    """OpenCV's calibrateRobotWorldHandEye, returned as `hand_eye` returns (X, Y)."""
    import cv2

    if mount == "tip":  # T_cam_board · T_board_base = T_cam_flange · T_flange_base
        A, B = T_cam_board, inverse(T_base_flange)
    else:  # T_cam_board · T_board_flange = T_cam_base · T_base_flange
        A, B = T_cam_board, T_base_flange
    Rb, tb, Rg, tg = cv2.calibrateRobotWorldHandEye(list(A[:, :3, :3]), list(A[:, :3, 3]), list(B[:, :3, :3]),
                                                    list(B[:, :3, 3]),
                                                    method=getattr(cv2, f"CALIB_ROBOT_WORLD_HAND_EYE_{method}"))
    # A X = Z B: A = T_cam_board, X = "base2world", Z = "gripper2cam", B = "base2gripper"
    X = homogeneous(Rb, tb.ravel())  # tip: T_board_base; world: T_board_flange
    Z = homogeneous(Rg, tg.ravel())  # tip: T_cam_flange; world: T_cam_base
    return inverse(Z), inverse(X)  # tip: T_flange_cam, T_base_board; world: T_base_cam, T_flange_board


def flange_poses(model, x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """T_root_tip (m,4,4) of the chain at x with its base and tool frames set to identity."""
    names = model.parameter_names()
    x0 = np.asarray(x, float)[:model.n_kin].copy()
    for f in ("base", "tool"):
        i = names.index(f"{f}.x")
        x0[i:i + 6] = 0.0
    R, p = ch.forward(model.kin.chain(), x0, q)
    return homogeneous(R, p)


def set_frames(model, x: np.ndarray, X: np.ndarray, Y: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Parameter vector x with the hand-eye solution (X, Y as `hand_eye`) and intrinsics k in it."""
    from pipeline.models.urdf import rpy_of

    x = np.asarray(x, float).copy()
    names = model.parameter_names()
    base = inverse(Y) if model.mount == "tip" else inverse(X)  # board←base / camera←base
    tool = X if model.mount == "tip" else Y  # flange→camera / flange→board
    for f, T in (("base", base), ("tool", tool)):
        i = names.index(f"{f}.x")
        x[i:i + 3] = T[:3, 3]
        x[i + 3:i + 6] = rpy_of(T[:3, :3])
    x[model.n_kin:] = k
    return x


def opencv_start(model, data: Table, method: str = "PARK") -> np.ndarray:
    """The parameter vector of OpenCV's two-step solution on `data` (nominal kinematics), with
    the distortion terms the model fits with its registration (pinhole: k1, k2, p1, p2; the
    others start at 0, where model selection frees them from)."""
    _, obj, px, q = views(data)
    nd = model.n_dist if model.lens == pj.FISHEYE else 4
    k0 = None if model.k_start is None or model.lens == pj.FISHEYE else np.asarray(model.k_start, float)
    k, T_cb, _ = calibrate_camera(obj, px, tuple(model.image_size), model.lens, nd, k0)
    x = model.nominal()
    X, Y = hand_eye(flange_poses(model, x, q), T_cb, model.mount, method)
    return set_frames(model, x, X, Y, np.r_[k, np.zeros(model.n_dist - nd)])
