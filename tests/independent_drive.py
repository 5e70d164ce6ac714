"""Independent generator of drive state: a URDF robot with compliant joints carrying a payload
its URDF does not describe, and the efforts its drives measure.

Shares no code with the diagnosis or robocal's simulator: forward kinematics from the URDF text with
its own 4×4 products (vectorised over configurations), the gravity torques as −∂V/∂q of the potential
energy V = Σ m·G·z_com (links and payload) by central differences (robocal sums cross products:
`pipeline.diagnose.library.urdf_gravity`), the deflection as a fixed point, and the efforts as what a drive
holding the link at standstill measures: effort = +∂V/∂q (N·m), plus noise.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
from r6_robot import INERTIAL, URDF

G = 9.80665


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], [-sp, cp * sr, cp * cr]])


def _joints(text: str = URDF) -> list[tuple[np.ndarray, np.ndarray, str]]:
    out = []
    for j in ET.fromstring(text).findall("joint"):
        o = j.find("origin")
        A = np.eye(4)
        A[:3, :3] = _rpy(*[float(v) for v in o.get("rpy", "0 0 0").split()])
        A[:3, 3] = [float(v) for v in o.get("xyz").split()]
        out.append((A, np.array([float(v) for v in j.find("axis").get("xyz").split()]), j.find("child").get("link")))
    return out


def potential(q: np.ndarray, payload_kg: float = 0.0, payload_com=(0.0, 0.0, 0.05), text: str = URDF) -> np.ndarray:
    """V(q) (n,) J: every link's inertial mass and the payload (at `payload_com` m in the tip frame) times G·z."""
    q = np.atleast_2d(q)
    n = q.shape[0]
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    V = np.zeros(n)
    for k, (A, ax, child) in enumerate(_joints(text)):
        K = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
        s, c = np.sin(q[:, k])[:, None, None], np.cos(q[:, k])[:, None, None]
        R = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        R[:, :3, :3] = np.eye(3) + s * K + (1 - c) * (K @ K)
        T = T @ A @ R
        m, com = INERTIAL[child]
        V += m * G * (T @ np.r_[[float(v) for v in com.split()], 1.0])[:, 2]
    return V + payload_kg * G * (T @ np.r_[np.asarray(payload_com, float), 1.0])[:, 2]


def holding_efforts(q: np.ndarray, payload_kg: float = 0.0, payload_com=(0.0, 0.0, 0.05), h: float = 1e-6) -> np.ndarray:
    """What each drive measures holding the arm still at true joints q (n, J): +∂V/∂q, N·m."""
    return np.stack([(potential(q + h * e, payload_kg, payload_com) - potential(q - h * e, payload_kg, payload_com))
                     / (2 * h) for e in np.eye(q.shape[1])], axis=1)


def deflected(q_read: np.ndarray, compliance: np.ndarray, payload_kg: float = 0.0, payload_com=(0.0, 0.0, 0.05)
              ) -> np.ndarray:
    """True joints: the reading plus c·(gravity torque −∂V/∂q) at the true joints (fixed point)."""
    q = np.array(q_read, float)
    for _ in range(4):
        q = q_read - compliance * holding_efforts(q, payload_kg, payload_com)
    return q


def standstill_stream(t_meas_ns: np.ndarray, q_read: np.ndarray, effort: np.ndarray, rng: np.random.Generator,
                      noise_nm: float, rate_hz: float = 200.0, dwell_s: float = 0.3) -> dict[str, np.ndarray]:
    """Samples every 1/rate_hz s over ±dwell_s/2 around each measurement: readings held, efforts + noise."""
    k = int(dwell_s * rate_hz)
    offs = ((np.arange(k) - k // 2) * (1e9 / rate_hz)).astype(np.int64)
    t = (np.asarray(t_meas_ns, np.int64)[:, None] + offs).ravel()
    rows = np.repeat(np.arange(len(q_read)), k)
    return {"t_ns": t, "q": q_read[rows], "q_cmd": q_read[rows],
            "effort": effort[rows] + rng.normal(0, noise_nm, (t.size, q_read.shape[1]))}
