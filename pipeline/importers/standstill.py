"""Pair each measurement with the joint state where the robot stood still around it.

A measurement at time t is paired when the joint states cover the window [t − w/2, t + w/2] (a
sample at or before its start, one at or after its end, no gap between consecutive samples longer
than w) and, over the samples inside the window, every joint's peak-to-peak motion divided by the
window length — its mean speed bound, rad/s for revolute joints, m/s for prismatic ones — is at most
`max_speed`.  The paired joint positions are the mean of the samples inside the window: the robot
being still they agree to the encoder noise, which the mean lowers, and a slow creep below the
threshold averages to the position at t (the window is centred on it).  A measurement the window
finds moving, or not covered by joint states, is excluded and reported — never paired.

Pure numpy: `np.searchsorted` finds every window's samples, `np.maximum.reduceat` /
`np.minimum.reduceat` take their extremes and a cumulative sum their mean; there is no Python loop
over measurements or joint samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DEFAULT_WINDOW_S = 0.5
DEFAULT_MAX_SPEED = 0.01  # rad/s (m/s for prismatic joints)


@dataclass(frozen=True)
class Pairing:
    """Result of `pair`: per measurement, whether it was paired and why not; the paired positions."""

    q: np.ndarray  # (m, n_joints) mean joint positions over each window (NaN where not paired)
    still: np.ndarray  # (m,) bool: paired
    moving: np.ndarray  # (m,) bool: covered by joint states but moving
    uncovered: np.ndarray  # (m,) bool: the joint states do not cover the window
    speed: np.ndarray  # (m,) largest joint's peak-to-peak / window over the window (rad/s or m/s; NaN if uncovered)
    fastest: np.ndarray  # (m,) index of that joint (-1 if uncovered)
    n_samples: np.ndarray  # (m,) joint samples inside each window
    window_s: float
    max_speed: float


def pair(t_joint: np.ndarray, q: np.ndarray, t_meas: np.ndarray, window_s: float = DEFAULT_WINDOW_S,
         max_speed: float = DEFAULT_MAX_SPEED) -> Pairing:
    """Pair measurements at `t_meas` (s, (m,)) with joint states `q` ((n, J), rad or m) at `t_joint`
    (s, (n,), sorted ascending, same clock) — see the module docstring for the rule."""
    t = np.asarray(t_joint, float)
    q = np.asarray(q, float)
    tm = np.asarray(t_meas, float)
    n, J = q.shape
    m = len(tm)
    if window_s <= 0 or max_speed <= 0:
        raise ValueError("window_s and max_speed must be positive")
    if n and np.any(np.diff(t) < 0):
        raise ValueError("joint times must be sorted")
    half = window_s / 2
    lo_t, hi_t = tm - half, tm + half
    # samples inside the window: [a, b)
    a = np.searchsorted(t, lo_t, side="left")
    b = np.searchsorted(t, hi_t, side="right")
    covered = (n > 0) & (b > a)
    if n:
        covered &= (t[0] <= lo_t) & (t[-1] >= hi_t)
        # the longest interval between consecutive samples that overlaps the window: intervals
        # k = a-1 … b-1 (interval k runs from t[k] to t[k+1])
        dt = np.append(np.diff(t), 0.0)  # dt[k] = t[k+1] - t[k]
        g0 = np.clip(a - 1, 0, n - 1)
        gap = _range_reduce(np.maximum, dt, g0, np.maximum(b, g0 + 1))
        covered &= gap <= window_s
    speed = np.full(m, np.nan)
    fastest = np.full(m, -1)
    qm = np.full((m, J), np.nan)
    if covered.any():
        ia, ib = a[covered], b[covered]
        hi = _range_reduce(np.maximum, q, ia, ib)
        lo = _range_reduce(np.minimum, q, ia, ib)
        ptp = (hi - lo) / window_s
        speed[covered] = ptp.max(axis=1)
        fastest[covered] = ptp.argmax(axis=1)
        csum = np.vstack([np.zeros((1, J)), np.cumsum(q, axis=0)])
        qm[covered] = (csum[ib] - csum[ia]) / (ib - ia)[:, None]
    still = covered & (speed <= max_speed)
    moving = covered & ~still
    qm[~still] = np.nan
    return Pairing(q=qm, still=still, moving=moving, uncovered=~covered, speed=speed, fastest=fastest,
                   n_samples=np.where(covered, b - a, 0), window_s=float(window_s), max_speed=float(max_speed))


def _range_reduce(ufunc: np.ufunc, x: np.ndarray, start: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """ufunc over x[start_i:stop_i] for every i (each range non-empty, stop ≤ len(x)), along axis 0:
    one `ufunc.reduceat` over the interleaved bounds (a sentinel row makes stop = len(x) valid)."""
    x = np.asarray(x)
    pad = np.concatenate([x, x[-1:]], axis=0)
    idx = np.empty(2 * len(start), np.intp)
    idx[0::2], idx[1::2] = start, stop
    return ufunc.reduceat(pad, idx, axis=0)[0::2]


def summary(p: Pairing, t_meas_s: np.ndarray, joint_names: list[str], t0_s: float = 0.0,
            listed: int = 50) -> dict:
    """The pairing as the recording's metadata and the import report (JSON-ready; times in s from
    `t0_s`, at most `listed` excluded measurements listed one by one)."""
    rel = np.asarray(t_meas_s, float) - t0_s
    mov = np.flatnonzero(p.moving)
    unc = np.flatnonzero(p.uncovered)
    return {
        "method": "standstill: joint states cover [t - w/2, t + w/2] and every joint's peak-to-peak motion "
                  "over it / w <= max_speed; paired joint positions = mean of the samples in the window",
        "window_s": p.window_s,
        "max_speed_rad_s_or_m_s": p.max_speed,
        "n_measurements": int(len(rel)),
        "n_paired": int(p.still.sum()),
        "n_moving": int(len(mov)),
        "n_not_covered": int(len(unc)),
        "max_speed_paired": float(np.max(p.speed[p.still])) if p.still.any() else None,
        "samples_per_window_min": int(p.n_samples[p.still].min()) if p.still.any() else None,
        "moving": [{"index": int(i), "t_s": round(float(rel[i]), 6), "speed": float(p.speed[i]),
                    "joint": joint_names[p.fastest[i]]} for i in mov[:listed]],
        "not_covered": [{"index": int(i), "t_s": round(float(rel[i]), 6)} for i in unc[:listed]],
    }
