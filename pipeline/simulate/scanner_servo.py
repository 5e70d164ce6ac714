"""Executing a planned scanner pose on the true arm: the operator's stripe servo.

A planned pose (`robocal plan scorbot-scanner`) is a joint configuration from the nominal model and
the grid line its stripe should lie on.  On the real robot the operator (or a visual servo) starts
there and moves the arm until the imaged stripe lies on that line; the simulator does the same on
the TRUE arm and scanner: minimum-norm Newton steps on the two laser-plane conditions of two points
of the line, from the planned joints, the planned crossings' middle at the image's centre column on the planned image row (lateral
shift and stand-off) (the operator watches the image:
the true camera, not the planning model's).  If the line cannot be reached within the joint limits, or
fewer than the required crossings are in the image, the pose is a miss (as a real search reports).
"""

from __future__ import annotations

import numpy as np

from pipeline.models import camera as cam
from pipeline.simulate.scanner_geometry import camera_pose as _camera_pose
from pipeline.simulate.scanner_geometry import newton as _newton
from pipeline.simulate.scanner_geometry import project as _project


def servo_pose(lower: np.ndarray, upper: np.ndarray, xa: np.ndarray, s: np.ndarray, pattern,
               q0: np.ndarray, line: np.ndarray, row: float, image_size: tuple[int, int], corners: int):
    """(q, corner indices) of the true arm (parameters `xa`, scanner `s`) with its stripe on the grid
    line through pattern corners `line` (first and last), its middle on image row `row` (px: the
    stand-off, as planned) at the centre column, started at the planned joints q0 (rad); the planned
    corners when all are in the image, else up to `corners` crossings nearest the image centre
    (at least 3); None when the servo fails or fewer than 3 crossings are visible."""
    W, H = image_size
    P = pattern.corners()
    A, B = P[int(line[0])], P[int(line[-1])]
    n_c, d_c = cam.laser_plane(s)
    M = (A + B) / 2  # the planned crossings' middle: at the image's centre column, on the planned row


    def on_plane(Q: np.ndarray) -> np.ndarray:
        Rc, Cc = _camera_pose(xa, s, Q)
        n = Rc @ n_c
        px = _project(Rc, Cc, s, np.broadcast_to(M, Cc.shape).copy())[0]
        k = s[cam.I_SU] / s[cam.I_F]  # pixels → rad (the others' scale)
        return np.stack([np.sum(n * (A - Cc), axis=1) - d_c, np.sum(n * (B - Cc), axis=1) - d_c,
                         (px[:, 0] - W / 2) * k, (px[:, 1] - row) * k], axis=1)

    q = _newton(on_plane, np.asarray(q0, float))
    if np.max(np.abs(on_plane(q[None]))) > 1e-10 or np.any(q < lower) or np.any(q > upper):
        return None
    u = (B - A) / np.linalg.norm(B - A)
    nrm = np.array([-u[1], u[0], 0.0])
    idx = np.flatnonzero(np.abs((P - A) @ nrm) < 1e-9)
    R_c, C = _camera_pose(xa, s, np.repeat(q[None], idx.size, axis=0))
    px, z = _project(R_c, C, s, P[idx])
    inside = (z > 0) & (px[:, 0] > 10) & (px[:, 0] < W - 11) & (px[:, 1] > 10) & (px[:, 1] < H - 11)
    idx, px = idx[inside], px[inside]
    if np.isin(line, idx).all() and len(line) >= corners:
        return q, np.sort(np.asarray(line, int))
    if idx.size < 3:
        return None
    keep = np.argsort(np.abs(px[:, 0] - W / 2))[:corners]
    return q, idx[np.sort(keep)]
