"""Motion context of each measurement, from the encoder stream around it.

What the diagnosis needs to name effects that depend on how the robot arrived at a
measurement: joint velocity (rad/s) and the sign of each joint's last motion (backlash),
and time since the start of the recording (thermal drift).  Vectorised with searchsorted.
"""

from __future__ import annotations

import numpy as np

from pipeline.ingest.streams import JointStream

ENCODER_COUNT_RAD = 2 * np.pi / 2**17


def last_motion_sign(t: np.ndarray, q: np.ndarray, t_ns: np.ndarray, threshold_rad: float = 3 * ENCODER_COUNT_RAD,
                     lookback_s: float = 60.0) -> np.ndarray:
    """Sign of each joint's last motion before each time, (n, nj) in {−1, 0, +1}.

    Looking back from the measurement, the latest sample at which the joint was more than
    `threshold_rad` away from its value at the measurement; the sign is that of (now − then),
    0 if there is none within `lookback_s`.  Unlike a per-sample step test this also sees slow
    motions (a joint creeping at less than one encoder count per sample during a search).
    One vectorised look-back window per measurement (all joints at once).
    """
    t_ns = np.asarray(t_ns, np.int64)
    n, nj = t_ns.size, q.shape[1]
    at = np.clip(np.searchsorted(t, t_ns, side="right") - 1, 0, t.size - 1)
    period_s = max(float(np.median(np.diff(t[: min(t.size, 1000)]))) * 1e-9, 1e-6) if t.size > 1 else 1.0
    w = int(max(1, np.ceil(lookback_s / period_s)))
    out = np.zeros((n, nj))
    for i in range(n):
        d = q[at[i]] - q[max(0, at[i] - w): at[i] + 1]  # (len, nj): now minus then
        far = np.abs(d) > threshold_rad
        last = far.shape[0] - 1 - np.argmax(far[::-1], axis=0)  # latest far sample per joint
        out[i] = np.where(far.any(axis=0), np.sign(d[last, np.arange(nj)]), 0.0)
    return out


def motion_context(stream: JointStream, t_ns: np.ndarray, window_s: float = 0.02) -> dict[str, np.ndarray]:
    """For measurement times `t_ns` (n,):

    - ``joint_velocity`` (n, nj) rad/s: central difference over ±`window_s` of the stream;
    - ``last_motion_sign`` (n, nj) in {−1, 0, +1}: see `last_motion_sign`;
    - ``time_since_start_s`` (n,): seconds since the first encoder sample.
    """
    t = stream.t_ns
    q = stream.q
    t_ns = np.asarray(t_ns, np.int64)
    w = int(window_s * 1e9)
    lo = np.clip(np.searchsorted(t, t_ns - w, side="left"), 0, t.size - 1)
    hi = np.clip(np.searchsorted(t, t_ns + w, side="right") - 1, 0, t.size - 1)
    dt = (t[hi] - t[lo]) * 1e-9
    vel = np.where(dt[:, None] > 0, (q[hi] - q[lo]) / np.where(dt > 0, dt, 1.0)[:, None], 0.0)
    return {"joint_velocity": vel, "last_motion_sign": last_motion_sign(t, q, t_ns),
            "time_since_start_s": (t_ns - t[0]) * 1e-9}
