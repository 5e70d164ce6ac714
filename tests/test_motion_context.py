"""Motion context: the sign of each joint's last motion, including slow creeping searches."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.ingest.context import ENCODER_COUNT_RAD, last_motion_sign

T0 = 1_767_225_600_000_000_000


def brute(t, q, t_ns, thr=3 * ENCODER_COUNT_RAD):
    out = np.zeros((len(t_ns), q.shape[1]))
    for i, tm in enumerate(t_ns):
        at = np.searchsorted(t, tm, side="right") - 1
        for j in range(q.shape[1]):
            for k in range(at, -1, -1):
                if not q[at, j] - thr <= q[k, j] <= q[at, j] + thr:  # outside [v − thr, v + thr]
                    out[i, j] = np.sign(q[at, j] - q[k, j])
                    break
    return out


def test_a_joint_creeping_below_one_count_per_sample_is_seen_moving():
    t = T0 + np.arange(2000, dtype=np.int64) * 4_000_000  # 250 Hz
    q = np.zeros((2000, 2))
    q[:1000, 0] = np.linspace(0.0, 0.5, 1000)  # fast up, then …
    q[1000:, 0] = 0.5 - 0.3 * ENCODER_COUNT_RAD * np.arange(1000)  # … a slow search down (0.3 count/sample)
    q[:, 1] = np.linspace(0.0, -0.2, 2000)
    s = last_motion_sign(t, q, np.array([t[1999]]))
    assert s.tolist() == [[-1.0, -1.0]]


@settings(max_examples=40, deadline=None)
@given(steps=st.lists(st.integers(-6, 6), min_size=20, max_size=120), seed=st.integers(0, 1000))
def test_matches_a_brute_force_look_back(steps, seed):
    rng = np.random.default_rng(seed)
    n = len(steps)
    q = np.stack([np.cumsum(steps), np.cumsum(rng.integers(-2, 3, n))], axis=1) * ENCODER_COUNT_RAD
    t = T0 + np.arange(n, dtype=np.int64) * 4_000_000
    t_ns = np.sort(rng.choice(t, size=min(8, n), replace=False))
    np.testing.assert_array_equal(last_motion_sign(t, q, t_ns), brute(t, q, t_ns))


def brute_window(t, q, t_ns, lookback_s, thr=3 * ENCODER_COUNT_RAD):
    period = np.median(np.diff(t[:1000])) * 1e-9
    w = int(max(1, np.ceil(lookback_s / period)))
    out = np.zeros((len(t_ns), q.shape[1]))
    for i, tm in enumerate(t_ns):
        at = np.searchsorted(t, tm, side="right") - 1
        for j in range(q.shape[1]):
            for k in range(at, max(0, at - w) - 1, -1):
                if not q[at, j] - thr <= q[k, j] <= q[at, j] + thr:  # outside [v − thr, v + thr]
                    out[i, j] = np.sign(q[at, j] - q[k, j])
                    break
    return out


@settings(max_examples=40, deadline=None)
@given(n=st.integers(50, 3000), lookback=st.floats(0.01, 20.0), hold=st.integers(0, 2000), seed=st.integers(0, 10**6))
def test_block_search_matches_a_brute_force_look_back_window(n, lookback, hold, seed):
    """Long streams with joints that stand still for a while (`hold` samples), so the window
    boundary and the block search (blocks of ≈ √window samples) are both exercised."""
    rng = np.random.default_rng(seed)
    steps = rng.integers(-4, 5, (n, 3)) * (rng.random((n, 3)) < 0.3)
    a = rng.integers(0, n)
    steps[a:a + hold] = 0  # a stretch of standstill: the last motion lies further back
    q = np.cumsum(steps, axis=0) * ENCODER_COUNT_RAD
    t = T0 + np.arange(n, dtype=np.int64) * 4_000_000
    t_ns = np.sort(rng.choice(t, size=min(30, n), replace=False))
    np.testing.assert_array_equal(last_motion_sign(t, q, t_ns, lookback_s=lookback), brute_window(t, q, t_ns, lookback))
