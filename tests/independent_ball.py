"""Ball-in-socket contacts of the r6 test arm with a ball on its flange, made without robocal's code: the URDF
read by `xml.etree`, forward kinematics as 4×4 products, each contact's joints solved so the *true* ball centre
sits in its socket (Gauss-Newton, the socket reached from several wrist attitudes), checked against yourdfpy's
forward kinematics, written as one CSV of joint angles per socket (`robocal import csv --measure coincidence`)."""

from __future__ import annotations

import io
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from r6_robot import BARE_URDF

JOINTS = ["j1", "j2", "j3", "j4", "j5", "j6"]
NOMINAL_BALL = (0.0, 0.0, 0.1)  # m: the ball centre in link l6 as drawn
LIMIT = np.array([3, 2, 2.5, 3, 2, np.pi])  # rad: the joints' limits (symmetric)


def ball_urdf(ball=NOMINAL_BALL) -> str:
    """The r6 arm with a fixed `ball_link` at `ball` (m) in l6."""
    joint = (f'  <joint name="ball" type="fixed"><parent link="l6"/><child link="ball_link"/>'
             f'<origin xyz="{ball[0]:.9g} {ball[1]:.9g} {ball[2]:.9g}"/></joint>\n')
    return BARE_URDF.replace('<link name="l6"/>', '<link name="l6"/><link name="ball_link"/>').replace(
        "</robot>", joint + "</robot>")


def _rot(axis, a: np.ndarray) -> np.ndarray:
    """Rotations (n, 3, 3) by angles a (n,) about the unit `axis` (Rodrigues)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    a = np.asarray(a, float)[:, None, None]
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * (K @ K)


def _rpy(r, p, y) -> np.ndarray:
    one = np.ones(1)
    return (_rot((0, 0, 1), y * one) @ _rot((0, 1, 0), p * one) @ _rot((1, 0, 0), r * one))[0]


def chain(urdf: str, tip: str = "ball_link") -> list[tuple]:
    """[(origin xyz, origin rotation, axis or None for a fixed joint)] from the root to `tip`."""
    by_child = {j.find("child").get("link"): j for j in ET.fromstring(urdf).iter("joint")}
    out, link = [], tip
    while link in by_child:
        j = by_child[link]
        o = j.find("origin")
        xyz = np.array([float(v) for v in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()])
        rpy = [float(v) for v in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()]
        ax = j.find("axis")
        axis = None if j.get("type") == "fixed" else [float(v) for v in (ax.get("xyz") if ax is not None else "1 0 0").split()]
        out.append((xyz, _rpy(*rpy), axis))
        link = j.find("parent").get("link")
    return out[::-1]


def ball_centres(links: list[tuple], q: np.ndarray) -> np.ndarray:
    """The tip's origin (n, 3) m in the root frame at joints q (n, 6)."""
    q = np.atleast_2d(q)
    R = np.broadcast_to(np.eye(3), (len(q), 3, 3)).copy()
    p = np.zeros((len(q), 3))
    k = 0
    for xyz, Ro, axis in links:
        p = p + R @ xyz
        R = R @ Ro
        if axis is not None:
            R = R @ _rot(axis, q[:, k])
            k += 1
    return p


def contacts(urdf: str, sockets: int = 3, per_socket: int = 10, seed: int = 0, noise_rad: float = 1e-5):
    """[(socket point (3,) m, joints (per_socket, 6) rad)]: per socket, joints from starts spread ±0.6 rad about
    one configuration solved so the true ball centre is the socket point, then joint noise added."""
    links = chain(urdf)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(sockets):
        q0 = rng.uniform([-2, -1, -1.5, -2, -1.2, -2], [2, 1, 1.5, 2, 1.2, 2])
        target = ball_centres(links, q0)[0]
        q = q0 + rng.uniform(-0.6, 0.6, (4 * per_socket, 6))
        for _ in range(60):  # Gauss-Newton, minimum-norm steps, central differences
            e = ball_centres(links, q) - target
            J = np.stack([(ball_centres(links, q + h) - ball_centres(links, q - h)) / 2e-7
                          for h in np.eye(6) * 1e-7], axis=2)
            q = q - np.einsum("nij,nj->ni", np.linalg.pinv(J), e)
        ok = (np.linalg.norm(ball_centres(links, q) - target, axis=1) < 1e-10) & np.all(np.abs(q) < 0.9 * LIMIT, axis=1)
        assert ok.sum() >= per_socket, ok.sum()
        q = q[ok][:per_socket]
        out.append((target, q + rng.normal(0, noise_rad, q.shape)))
    return out


def check_with_yourdfpy(urdf: str, target: np.ndarray, q: np.ndarray, tol: float) -> float:
    """Largest distance (m) of yourdfpy's ball centre from `target` over the rows of q."""
    import yourdfpy

    u = yourdfpy.URDF.load(io.StringIO(urdf))
    worst = 0.0
    for row in q:
        u.update_cfg(dict(zip(JOINTS, row)))
        worst = max(worst, float(np.linalg.norm(u.get_transform("ball_link", "b")[:3, 3] - target)))
    assert worst < tol, worst
    return worst


def write_sockets(folder: Path, data: list) -> list[Path]:
    """hole_k.csv (joint angles, no header) per socket."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for k, (_, q) in enumerate(data):
        p = folder / f"hole_{k}.csv"
        p.write_text("\n".join(",".join(f"{v:.12g}" for v in row) for row in q) + "\n")
        paths.append(p)
    return paths
