"""Motion context of each measurement, from the encoder stream around it.

What the diagnosis needs to name effects that depend on how the robot arrived at a
measurement: joint velocity (rad/s) and the sign of each joint's last motion (backlash),
and time since the start of the recording (thermal drift).  Vectorised with searchsorted.
"""

from __future__ import annotations

import numpy as np

from pipeline.ingest.streams import JointStream

ENCODER_COUNT_RAD = 2 * np.pi / 2**17


def _outside(q: np.ndarray, v: np.ndarray, thr: float) -> np.ndarray:
    """q outside [v − thr, v + thr]; written one-sided, exactly as the block min/max test, so
    that a difference of exactly the threshold (quantised encoders) is decided the same way."""
    return (q < v - thr) | (q > v + thr)


NOISE_K = 6.0  # a motion: beyond this many σ of the stream's own noise (`stream_noise_rad`)


def stream_noise_rad(q: np.ndarray) -> np.ndarray:
    """(nj,) rad: each joint's reading noise in an encoder stream, robustly from its second differences (a smooth
    motion's are ≈ 0; white noise of σ gives var 6σ²): 1.4826·MAD(Δ²q)/√6.  0 for a clean quantised stream (its
    second differences are mostly 0 counts)."""
    q = np.asarray(q, float)
    if q.shape[0] < 3:
        return np.zeros(q.shape[1])
    d2 = np.diff(q, 2, axis=0)
    return 1.4826 * np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0) / np.sqrt(6.0)


def motion_threshold(q: np.ndarray, floor_rad: float = 3 * ENCODER_COUNT_RAD) -> np.ndarray:
    """(nj,) rad: the smallest displacement `last_motion_sign` counts as a motion — 3 counts, or `NOISE_K` σ of
    the stream's noise where the readings are noisy (a resolver, an interpolated encoder): a noise spike is no
    motion."""
    return np.maximum(floor_rad, NOISE_K * stream_noise_rad(q))


def last_motion_sign(t: np.ndarray, q: np.ndarray, t_ns: np.ndarray,
                     threshold_rad: float | np.ndarray = 3 * ENCODER_COUNT_RAD, lookback_s: float = 60.0) -> np.ndarray:
    """Sign of each joint's last motion before each time, (n, nj) in {−1, 0, +1}.

    Looking back from the measurement, the latest sample at which the joint was more than
    `threshold_rad` (one value, or one per joint) away from its value v at the measurement (outside
    [v − thr, v + thr]); the sign is that of (now − then), 0 if there is none within `lookback_s`.  Unlike a per-sample step test this also sees slow
    motions (a joint creeping at less than one encoder count per sample during a search).

    Vectorised over measurements with a two-level search: the stream is cut into blocks of
    ≈ √window samples whose min/max say whether a block holds a far sample; per measurement
    and joint, the measurement's own (partial) block is searched sample by sample, else the
    latest far block within the window, then that block's samples — O(n·(√w)·nj) work instead
    of O(n·w·nj) for a window of w samples.
    """
    t = np.asarray(t, np.int64)
    q = np.asarray(q, float)
    t_ns = np.asarray(t_ns, np.int64)
    n, nj = t_ns.size, q.shape[1]
    threshold_rad = np.broadcast_to(np.asarray(threshold_rad, float), (nj,))
    thr_j = threshold_rad[:, None]  # (nj, 1): against (m, nj, B) samples
    if n == 0 or t.size == 0:
        return np.zeros((n, nj))
    at = np.clip(np.searchsorted(t, t_ns, side="right") - 1, 0, t.size - 1)
    period_s = max(float(np.median(np.diff(t[: min(t.size, 1000)]))) * 1e-9, 1e-6) if t.size > 1 else 1.0
    w = int(max(1, np.ceil(lookback_s / period_s)))
    B = int(max(16, np.ceil(np.sqrt(w))))
    nb = -(-t.size // B)
    qp = np.concatenate([q, np.repeat(q[-1:], nb * B - t.size, axis=0)])  # pad: only ever inside a measurement's own block
    blocks = np.ascontiguousarray(qp.T).reshape(nj, nb, B)  # joint-major: contiguous reductions
    bmin, bmax = blocks.min(axis=2).T, blocks.max(axis=2).T  # (nb, nj)
    L = -(-w // B) + 2  # blocks a window can reach before the measurement's own
    ar, cols = np.arange(B), np.arange(nj)
    out = np.zeros((n, nj))
    for c in range(0, n, 1024):  # chunks bound the (chunk, B, nj) temporaries
        a = at[c:c + 1024]
        s = np.maximum(0, a - w)
        v = q[a]  # (m, nj) value at the measurement
        ba, bs = a // B, s // B
        # 1. the measurement's own block, samples s ≤ k ≤ a
        idx = ba[:, None] * B + ar
        ok = (idx <= a[:, None]) & (idx >= s[:, None])
        far = _outside(qp[idx], v[:, None, :], threshold_rad) & ok[:, :, None]  # (m, B, nj)
        found1 = far.any(axis=1)
        k1 = ba[:, None] * B + (B - 1 - np.argmax(far[:, ::-1, :], axis=1))
        # 2. else the latest earlier block (≥ bs) whose range leaves v ± threshold, then its samples ≥ s
        bidx = ba[:, None] - 1 - np.arange(L)  # (m, L), latest first
        bc = np.clip(bidx, 0, nb - 1)
        farb = ((bmin[bc] < v[:, None, :] - threshold_rad) | (bmax[bc] > v[:, None, :] + threshold_rad)) \
            & (bidx >= bs[:, None])[:, :, None]  # (m, L, nj)
        blk = np.take_along_axis(bc, np.argmax(farb, axis=1), axis=1)  # (m, nj)
        idx2 = blk[:, :, None] * B + ar  # (m, nj, B)
        far2 = _outside(qp[idx2, cols[None, :, None]], v[:, :, None], thr_j) & (idx2 >= s[:, None, None])
        found2 = farb.any(axis=1) & far2.any(axis=2)
        k2 = blk * B + (B - 1 - np.argmax(far2[:, :, ::-1], axis=2))
        k = np.where(found1, k1, k2)
        d = v - q[np.minimum(k, t.size - 1), cols]
        out[c:c + 1024] = np.where(found1 | found2, np.sign(d), 0.0)
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
