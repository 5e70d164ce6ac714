"""Point measurements of the r6 test arm made with yourdfpy's forward kinematics (no robocal code):
the tool point of link l6 seen by an instrument placed off the robot base, with Gaussian noise,
written as a CSV table `robocal import csv` reads."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from r6_robot import BARE_URDF

JOINTS = ["j1", "j2", "j3", "j4", "j5", "j6"]
LOWER = np.array([-3, -2, -2.5, -3, -2, -np.pi])
UPPER = np.array([3, 2, 2.5, 3, 2, np.pi])


def tool_points(q: np.ndarray, tool=(0.03, -0.02, 0.05)) -> np.ndarray:
    """Tool point (m) in the base frame b at each configuration (n, 6) by yourdfpy."""
    import io

    import yourdfpy

    u = yourdfpy.URDF.load(io.StringIO(BARE_URDF))
    out = []
    for row in q:
        u.update_cfg(dict(zip(JOINTS, row)))
        T = u.get_transform("l6", "b")
        out.append(T[:3, :3] @ np.asarray(tool) + T[:3, 3])
    return np.array(out)


def instrument(p: np.ndarray, yaw: float = 0.7, t=(1.2, -0.4, 0.1)) -> np.ndarray:
    """The points seen from an instrument turned by `yaw` about z and shifted by t (m)."""
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    return (p - np.asarray(t)) @ R  # R^T (p - t)


def campaign(n: int, seed: int = 0, noise_m: float = 2e-5) -> tuple[np.ndarray, np.ndarray]:
    """(joints (n, 6) rad, measured points (n, 3) m) at random configurations."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(0.8 * LOWER, 0.8 * UPPER, (n, 6))
    return q, instrument(tool_points(q)) + rng.normal(0, noise_m, (n, 3))


def write_csv(path: Path, q: np.ndarray, p: np.ndarray, *, length_scale: float = 1.0, joint_scale: float = 1.0,
              swap: tuple[int, int] | None = None) -> Path:
    """x,y,z,j1..j6 rows; `length_scale`/`joint_scale` multiply the written values (a unit the
    header does not say), `swap` exchanges two position columns."""
    p = np.asarray(p, float) * length_scale
    if swap is not None:
        p = p.copy()
        p[:, list(swap)] = p[:, list(swap[::-1])]
    rows = ["x,y,z," + ",".join(JOINTS)]
    rows += [",".join(f"{v:.12g}" for v in (*a, *(b * joint_scale))) for a, b in zip(p, q)]
    path.write_text("\n".join(rows) + "\n")
    return path
