"""Simulated camera calibration campaigns with known truth: images of a chessboard rendered by
OpenCV from a simulated URDF robot (any intrinsics, distortion, hand-eye, joint offset errors).

Rendering (`render`): each output pixel's ray is undistorted (`cv2.undistortPointsIter`, the
lens's exact inverse), intersected with the board plane and looked up in a board texture
(`cv2.remap`, bilinear) at `supersample`× the resolution, then averaged down (`cv2.resize`,
area), blurred (Gaussian, `blur_px` σ) and given Gaussian grey-level noise (`noise` σ, of 255) —
no corner position is computed by robocal's own projection.  The truth's corner pixels are the
projection of the board corners; a detector's error is measured against them.

Campaign (`poses`): robot configurations drawn around a home configuration where the camera
sees the board, kept when every corner is inside the image, ≥ `margin_px` from its border, and
the board faces the camera.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.camera import projection as pj
from pipeline.camera.targets import Target

WHITE, BLACK = 235, 20


def board_texture(target: Target, ppm: float) -> tuple[np.ndarray, float]:
    """The chessboard as a grey image: inner corner (0, 0) at texture pixel origin + 2 squares;
    returns the image and its metres per texture pixel.  Squares: (COLS+1)×(ROWS+1), one white
    square of margin around them."""
    s = target.square_m
    res = s / ppm
    w, h = int(round((target.cols + 3) * ppm)), int(round((target.rows + 3) * ppm))
    X = (np.arange(w) + 0.5) * res - 2 * s
    Y = (np.arange(h) + 0.5) * res - 2 * s
    i, j = np.floor(X / s).astype(int), np.floor(Y / s).astype(int)
    inside = ((i[None, :] >= -1) & (i[None, :] <= target.cols - 1) & (j[:, None] >= -1) & (j[:, None] <= target.rows - 1))
    black = ((i[None, :] + j[:, None]) % 2 == 0) & inside
    return np.where(black, BLACK, WHITE).astype(np.float32), res


def rays(k: np.ndarray, lens: str, size: tuple[int, int], supersample: int = 2) -> np.ndarray:
    """Undistorted normalised rays (x, y, 1) of every (sub)pixel, (h·S·w·S, 3): the lens's exact
    inverse (`cv2.undistortPointsIter` / `cv2.fisheye.undistortPoints`); shared by all images of a camera."""
    import cv2

    w, h = size
    S = supersample
    u, v = np.meshgrid((np.arange(w * S) + 0.5) / S - 0.5, (np.arange(h * S) + 0.5) / S - 0.5)
    pts = np.stack([u.ravel(), v.ravel()], 1)[:, None, :].astype(np.float64)
    K = pj.camera_matrix(k)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)
    if lens == pj.FISHEYE:
        n = cv2.fisheye.undistortPoints(pts, K, k[4:], criteria=crit).reshape(-1, 2)
    else:
        n = cv2.undistortPointsIter(pts, K, k[4:], None, None, crit).reshape(-1, 2)
    return np.c_[n, np.ones(len(n))]


def render(k: np.ndarray, lens: str, T_cam_board: np.ndarray, target: Target, size: tuple[int, int],
           blur_px: float = 0.6, noise: float = 2.0, rng: np.random.Generator | None = None,
           supersample: int = 2, ray_table: np.ndarray | None = None) -> np.ndarray:
    """An 8-bit grey image (height, width) of the board at T_cam_board (module docstring);
    `ray_table`: `rays(k, lens, size, supersample)` if already computed."""
    import cv2

    w, h = size
    S = supersample
    d = rays(k, lens, size, S) if ray_table is None else ray_table
    R, t = T_cam_board[:3, :3], T_cam_board[:3, 3]
    lam = (R[:, 2] @ t) / (d @ R[:, 2])
    Pb = (lam[:, None] * d - t) @ R  # board coordinates of each ray's hit
    tex, res = board_texture(target, ppm=24)
    mx = ((Pb[:, 0] + 2 * target.square_m) / res - 0.5).reshape(h * S, w * S).astype(np.float32)
    my = ((Pb[:, 1] + 2 * target.square_m) / res - 0.5).reshape(h * S, w * S).astype(np.float32)
    behind = (lam <= 0).reshape(h * S, w * S)
    mx[behind] = -1e6
    img = cv2.remap(tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=128)
    img = cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)
    if blur_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_px)
    if noise > 0:
        img = img + (rng or np.random.default_rng(0)).normal(0, noise, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def visible(k: np.ndarray, lens: str, T_cam_board: np.ndarray, target: Target, size: tuple[int, int],
            margin_px: float = 20.0) -> bool:
    """Every corner in front of the camera, inside the image by `margin_px`, the board seen at < 70° incidence."""
    P = target.points @ T_cam_board[:3, :3].T + T_cam_board[:3, 3]
    t = T_cam_board[:3, 3]
    if np.any(P[:, 2] < 0.05) or abs(T_cam_board[:3, 2] @ t) < 0.35 * np.linalg.norm(t):  # seen at < 70° incidence
        return False
    uv = pj.project(k, P, lens)
    return bool(np.all((uv > margin_px) & (uv < np.array(size) - margin_px)))


def board_in_camera(model, x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """T_cam_board (m,4,4) of the camera measurement model at x for configurations q."""
    from pipeline.camera.start import homogeneous, inverse
    from pipeline.models import chain as ch

    R, p = ch.forward(model.kin.chain(), model.split(x)[0], q)
    T = homogeneous(R, p)  # tip: T_board_cam; world: T_cam_board
    return inverse(T) if model.mount == "tip" else T


def poses(model, x: np.ndarray, q_home: np.ndarray, n: int, target: Target, rng: np.random.Generator,
          spread_rad: float = 0.25, max_tries: int = 200_000) -> np.ndarray:
    """n configurations (n, n_joints) around q_home from which the camera sees the whole board."""
    k = model.split(x)[1]
    out: list[np.ndarray] = []
    lo, hi = model.kin.lower, model.kin.upper
    for _ in range(max_tries // 256):
        q = np.clip(q_home + rng.normal(0, spread_rad, (256, q_home.size)), lo, hi)
        T = board_in_camera(model, x, q)
        for i in range(len(q)):
            if visible(k, model.lens, T[i], target, model.image_size):
                out.append(q[i])
                if len(out) == n:
                    return np.array(out)
    raise RuntimeError(f"only {len(out)} of {n} configurations see the board; widen the spread or move the board")


def write_campaign(folder: Path, model, x: np.ndarray, q: np.ndarray, target: Target, rng: np.random.Generator,
                   blur_px: float = 0.6, noise: float = 2.0, fmt: str = "png") -> list[Path]:
    """Render one image per configuration into `folder` (img_000.png …) and the joints CSV
    (``joints.csv``: image, then the chain's joints in rad); returns the image paths."""
    import cv2

    folder.mkdir(parents=True, exist_ok=True)
    k = model.split(x)[1]
    T = board_in_camera(model, x, q)
    table = rays(k, model.lens, model.image_size)
    files = []
    for i in range(len(q)):
        f = folder / f"img_{i:03d}.{fmt}"
        cv2.imwrite(str(f), render(k, model.lens, T[i], target, model.image_size, blur_px, noise, rng, ray_table=table))
        files.append(f)
    names = model.kin.joint_names
    lines = ["image," + ",".join(names)] + [f"{f.name}," + ",".join(repr(float(v)) for v in qi) for f, qi in zip(files, q)]
    (folder / "joints.csv").write_text("\n".join(lines) + "\n")
    return files


def truth(model, q_home: np.ndarray, k: np.ndarray, target: Target, rng: np.random.Generator,
          distance_m: float = 0.5, error_m: float = 5e-4, error_rad: float = 2e-3) -> np.ndarray:
    """A true parameter vector: the nominal robot plus N(0, error) on joint origins and offsets,
    a random hand-eye (camera or board ≈ 5 cm off the flange, rotations ≈ 0.1 rad), intrinsics k,
    and the board (tip) or camera (world) placed so that at q_home the board's centre is
    `distance_m` in front of the camera, facing it (`place_board`)."""
    from pipeline.models.urdf import matrix_of_rpy, rpy_of
    from pipeline.simulate.urdf_robot import random_truth

    x = random_truth(model, rng, error_m, error_rad, registration=False)
    names = model.parameter_names()
    it = names.index("tool.x")
    x[it:it + 3] = rng.normal(0, 0.05, 3)
    x[it + 3:it + 6] = rng.normal(0, 0.1, 3)
    if model.mount == "world":  # the board on the flange, facing back along the flange z
        x[it + 3:it + 6] = rpy_of(np.diag([1.0, -1.0, -1.0]) @ matrix_of_rpy(*rng.normal(0, 0.1, 3)))
    x[model.n_kin:] = k
    return place_board(model, x, q_home, target, distance_m)


def place_board(model, x: np.ndarray, q_home: np.ndarray, target: Target, distance_m: float) -> np.ndarray:
    """x with the chain's base frame (board → robot base, eye-in-hand; camera → robot base,
    eye-to-hand) set so that at q_home the board's centre is `distance_m` in front of the camera,
    the board's axes along the camera's."""
    from pipeline.camera.start import homogeneous, inverse
    from pipeline.models import chain as ch
    from pipeline.models.urdf import rpy_of

    x = np.array(x, float)
    ib = model.parameter_names().index("base.x")
    x[ib:ib + 6] = 0.0
    R, p = ch.forward(model.kin.chain(), model.split(x)[0], np.asarray(q_home, float)[None])
    T_base_tool = homogeneous(R[0], p[0])
    T_cam_board = homogeneous(np.eye(3), np.array([0.0, 0.0, distance_m]) - target.points.mean(0))
    B = inverse(T_base_tool @ T_cam_board) if model.mount == "tip" else T_cam_board @ inverse(T_base_tool)
    x[ib:ib + 3] = B[:3, 3]
    x[ib + 3:ib + 6] = rpy_of(B[:3, :3])
    return x
