"""Device clock correction: a 10-minute campaign with 100 ppm drift and a 2 s offset, run on
simulated time through the same acquisition core the `acquire` command uses."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.acquire import protocol as P
from pipeline.acquire.clock import ClockSync, lower_hull
from pipeline.acquire.session import Acquisition, strictly_increasing
from pipeline.recording.reader import read_recording
from pipeline.recording.writer import RecordingWriter

T0 = 1_795_000_000_000_000_000  # host ns
MS = 1_000_000


def _campaign(rng, minutes=10.0, rate=1000, batch=10, offset_ns=2_000_000_000, drift=100e-6):
    n = int(minutes * 60 * rate)
    t = T0 + np.arange(n, dtype=np.int64) * (1_000_000_000 // rate)  # true sample times (host clock)
    d = t + offset_ns + np.round((t - T0) * drift).astype(np.int64)  # device clock
    q = np.cumsum(rng.normal(0, 1e-3, (n, 6)), axis=0)
    frames, t_send = [], []
    for seq, s in enumerate(range(0, n, batch)):
        sl = slice(s, s + batch)
        frames.append(P.encode_frame(P.FrameType.SAMPLES, seq + 1, int(d[sl][-1]), P.encode_samples(d[sl], q[sl])))
        t_send.append(t[sl][-1])
    hello = P.encode_frame(P.FrameType.HELLO, 0, int(d[0]), P.encode_json(
        {"device": "bridge", "joint_names": [f"J{i}" for i in range(1, 7)]}))
    t_send = np.array(t_send)
    # transport: 30 µs floor + exponential jitter, 2 % of frames held up to 50 ms, FIFO
    lat = 30_000 + rng.exponential(300_000, t_send.size).astype(np.int64)
    late = rng.random(t_send.size) < 0.02
    lat[late] += rng.integers(0, 50 * MS, late.sum())
    arrive = np.maximum.accumulate(t_send + lat)
    # the host reads whatever has arrived every 1–10 ms
    reads = T0 + np.cumsum(rng.integers(1 * MS, 10 * MS, int(minutes * 60 * 200) + 1000))
    read_of = np.searchsorted(reads, arrive)
    return t, d, q, [hello] + frames, np.concatenate([[read_of[0]], read_of]), reads


@pytest.fixture(scope="module")
def drifted(tmp_path_factory):
    rng = np.random.default_rng(11)
    t, d, q, frames, read_of, reads = _campaign(rng)
    out = tmp_path_factory.mktemp("clock") / "drift.mcap"
    with open(out, "wb") as f:
        acq = Acquisition(RecordingWriter(f), {"bridge": "sim"})
        next_tick = reads[0] + 500 * MS
        bounds = np.flatnonzero(np.diff(read_of)) + 1
        for chunk in np.split(np.arange(len(frames)), bounds):
            h = int(reads[read_of[chunk[0]]])
            if h >= next_tick:  # the shell ticks every 0.5 s of host time
                acq.tick()
                next_tick = h + 500 * MS
            acq.on_bytes("bridge", b"".join(frames[i] for i in chunk), h)
        summary = acq.finish("test")
    return t, d, q, read_recording(out), summary


def test_timestamps_corrected_within_1ms_over_10_minutes(drifted):
    t, d, q, rec, summary = drifted
    msgs = rec.messages["/robot/joint_state"]
    ts = np.concatenate([m["timestamps_ns"] for m in msgs])
    raw = np.concatenate([m["device_timestamps_ns"] for m in msgs])
    assert ts.size == t.size == 600_000
    assert np.array_equal(raw, d)  # raw device clock kept
    assert np.array_equal(np.concatenate([m["positions"] for m in msgs]), q)
    err = np.abs(ts - t)
    assert np.max(np.abs(raw - t)) > 2_000_000_000  # uncorrected: over 2 s off
    assert err.max() < 1 * MS, f"max error {err.max() / 1e6:.3f} ms"
    assert np.all(np.diff(ts) > 0)
    clk = summary["devices"]["bridge"]["clock"]
    assert abs(clk["drift_ppm"] - (1e6 / (1 + 1e-4) - 1e6)) < 2.0  # host per device tick: −99.99 ppm


def test_clock_metadata_recorded(drifted):
    _, _, _, rec, _ = drifted
    dev = rec.meta("robocal.acquisition")["devices"]["bridge"]
    assert dev["missing_frames"] == 0 and dev["bad_frames"] == 0
    assert abs(dev["clock"]["offset_ns"] + 2_000_000_000) < 1 * MS


def test_lower_hull_and_late_outliers():
    rng = np.random.default_rng(3)
    x = np.sort(rng.uniform(0, 100, 5000))
    y = 0.5 + 1e-4 * x + rng.exponential(1e-3, x.size)
    y[::50] += 5.0  # grossly late frames do not matter
    cs = ClockSync()
    d = np.round(x * 1e9).astype(np.int64)
    cs.add(d, d + np.round(y * 1e9).astype(np.int64))
    fit = cs.fit()
    assert abs(fit.drift - 1e-4) < 2e-6
    assert np.max(np.abs((fit.to_host(d) - d) / 1e9 - (0.5 + 1e-4 * x))) < 2e-4
    h = lower_hull(x, y)
    assert np.all(np.diff(x[h]) > 0) and h.size < 100


def test_strictly_increasing():
    assert strictly_increasing(np.array([5, 5, 4, 10]), None).tolist() == [5, 6, 7, 10]
    assert strictly_increasing(np.array([5, 9]), 7).tolist() == [8, 9]


def test_acquired_stream_is_protobuf_with_device_and_host_times(drifted):
    """The acquisition writes the stream as robocal.JointStateBatch, with the raw device times and
    host receive times of every sample beside the corrected ones; `joint_stream` reads it."""
    from pipeline.ingest import streams
    from pipeline.recording import joint_state_batch as JSB

    rec = drifted[3]
    assert rec.encodings[streams.JOINT_STATE] == "protobuf" and not rec.registration[streams.JOINT_STATE]
    b = JSB.decode(rec.messages.raw[streams.JOINT_STATE])
    s = streams.joint_stream(rec)
    assert np.array_equal(s.t_ns, b.t_ns) and np.array_equal(s.q.view(np.int64), b.q.view(np.int64))
    assert b.device_t_ns.shape == b.host_t_ns.shape == s.t_ns.shape
    assert np.all(np.diff(s.t_ns) > 0) and not np.array_equal(b.device_t_ns, s.t_ns)
