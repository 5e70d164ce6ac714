"""Motion context of each measurement, from the encoder stream around it.

What the diagnosis needs to name effects that depend on how the robot arrived at a
measurement: joint velocity (rad/s) and the sign of each joint's last motion (backlash),
and time since the start of the recording (thermal drift).  Vectorised with searchsorted.
"""

from __future__ import annotations

import numpy as np

from pipeline.ingest.streams import JointStream

MOTION_DEADBAND_RAD = 2 * np.pi / 2**17 * 3  # a step smaller than 3 encoder counts is not motion


def motion_context(stream: JointStream, t_ns: np.ndarray, window_s: float = 0.02) -> dict[str, np.ndarray]:
    """For measurement times `t_ns` (n,):

    - ``joint_velocity`` (n, nj) rad/s: central difference over ±`window_s` of the stream;
    - ``last_motion_sign`` (n, nj) in {−1, 0, +1}: sign of each joint's most recent motion
      larger than the dead band before the measurement (0 if it never moved);
    - ``time_since_start_s`` (n,): seconds since the first encoder sample.
    """
    t = stream.t_ns
    q = stream.q
    t_ns = np.asarray(t_ns, np.int64)
    n, nj = t_ns.size, q.shape[1]
    w = int(window_s * 1e9)
    lo = np.clip(np.searchsorted(t, t_ns - w, side="left"), 0, t.size - 1)
    hi = np.clip(np.searchsorted(t, t_ns + w, side="right") - 1, 0, t.size - 1)
    dt = (t[hi] - t[lo]) * 1e-9
    vel = np.where(dt[:, None] > 0, (q[hi] - q[lo]) / np.where(dt > 0, dt, 1.0)[:, None], 0.0)

    # last motion sign: per joint, index of the last sample (at or before t) whose step exceeds the dead band
    step = np.diff(q, axis=0)  # step[k] = q[k+1] - q[k]
    moving = np.abs(step) > MOTION_DEADBAND_RAD / 3  # per-sample steps are small at 250 Hz; see below
    at = np.clip(np.searchsorted(t, t_ns, side="right") - 1, 0, t.size - 1)  # last sample at or before t
    sign = np.zeros((n, nj))
    for j in range(nj):  # loop over joints only (≤ 6), vectorised over measurements
        idx = np.flatnonzero(moving[:, j])
        if idx.size == 0:
            continue
        k = np.searchsorted(idx, at, side="left") - 1  # last moving step strictly before sample `at`
        ok = k >= 0
        sign[ok, j] = np.sign(step[idx[k[ok]], j])
    return {"joint_velocity": vel, "last_motion_sign": sign,
            "time_since_start_s": (t_ns - t[0]) * 1e-9}
