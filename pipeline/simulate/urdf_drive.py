"""Drive state of a simulated URDF robot: joint compliance, an unmodelled payload, and the
stream a controller logs while the robot stands at each measurement.

The *true* robot: joint j of compliance c_j (rad/(N·m)) deflects under the gravity torque τ_j of the
links it carries and of a payload at the tip (mass kg, centre of mass m in the tip link's frame) —
a payload the recording's URDF does not describe.  The controller logs, at `rate_hz` over `dwell_s`
around each measurement: the encoder reading, the commanded position and the measured effort, the
drive's torque on the link, which at standstill balances gravity: effort = −τ (N·m) plus noise.
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.library.urdf_gravity import gravity_torques


def parse_compliance(text: str, joints: list[str]) -> np.ndarray:
    """'j2=2e-6,j3=1e-6' → (J,) rad/(N·m) in chain order; ValueError naming a bad entry."""
    c = np.zeros(len(joints))
    for part in filter(None, (p.strip() for p in text.split(","))):
        name, _, v = part.partition("=")
        if name.strip() not in joints:
            raise ValueError(f"--compliance {part!r}: {name.strip()!r} is not a chain joint ({', '.join(joints)})")
        try:
            c[joints.index(name.strip())] = float(v)
        except ValueError:
            raise ValueError(f"--compliance {part!r}: expected JOINT=VALUE, rad/(N·m)") from None
        if not np.isfinite(c[joints.index(name.strip())]) or c[joints.index(name.strip())] < 0:
            raise ValueError(f"--compliance {part!r}: a compliance is a finite value ≥ 0, rad/(N·m)")
    return c


def true_torques(desc, q_true: np.ndarray, payload: tuple[float, np.ndarray] | None = None) -> np.ndarray:
    """Gravity torques (n, J) N·m of the true robot (URDF inertials plus the payload) at its true joints."""
    return gravity_torques(desc, q_true, payload=payload)


def deflect(desc, q_read: np.ndarray, compliance: np.ndarray, payload: tuple[float, np.ndarray] | None = None,
            iters: int = 4) -> np.ndarray:
    """Where the joints truly stand (n, J) rad: the reading plus c·τ(q_true) (a fixed point: the
    deflection moves the links the torques come from)."""
    q_read = np.asarray(q_read, float)
    c = np.asarray(compliance, float)
    if not c.any():
        return q_read.copy()
    q = q_read.copy()
    for _ in range(iters):
        q = q_read + c * true_torques(desc, q, payload)
    return q


def drive_stream(t_meas_ns: np.ndarray, q_read: np.ndarray, q_cmd: np.ndarray | None, effort: np.ndarray | None,
                 rng: np.random.Generator, effort_noise: float = 0.0, rate_hz: float = 250.0,
                 dwell_s: float = 0.4) -> dict[str, np.ndarray]:
    """The encoder stream (for `write_urdf_recording`'s `stream`) at standstill around each measurement:
    samples every 1/rate_hz s over ±dwell_s/2 of its time, readings and commands held, efforts (n, J)
    N·m plus N(0, effort_noise) per sample.  Measurements must be more than `dwell_s` apart."""
    t_meas_ns = np.asarray(t_meas_ns, np.int64)
    k = max(int(round(dwell_s * rate_hz)), 1)
    offs = np.round((np.arange(k) - (k - 1) / 2) * 1e9 / rate_hz).astype(np.int64)
    t = (t_meas_ns[:, None] + offs).ravel()
    if np.any(np.diff(t) <= 0):
        raise ValueError("measurements closer than the dwell: the stream's sample times would not increase")
    rows = np.repeat(np.arange(t_meas_ns.size), k)
    out = {"t_ns": t, "q": np.asarray(q_read, float)[rows]}
    if q_cmd is not None:
        out["q_cmd"] = np.asarray(q_cmd, float)[rows]
    if effort is not None:
        e = np.asarray(effort, float)[rows]
        out["effort"] = e + rng.normal(0, effort_noise, e.shape) if effort_noise else e
    return out
