"""Benchmark: ingest rate of the encoder stream (MCAP → numpy), target ≥ 1 M samples/s.

Run: .venv/bin/python benchmarks/bench_ingest.py
Writes a 1.2 M-sample, 6-joint, 250 Hz stream (80 min of controller data) with the real
writer, then times `read_recording` + `joint_stream` (best of 3).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from pipeline.ingest.streams import joint_stream
from pipeline.recording.reader import read_recording
from pipeline.recording.schemas import META_CAMPAIGN
from pipeline.recording.writer import write_campaign

N = 1_200_000


def main() -> None:
    t_ns = 1_767_225_600_000_000_000 + np.arange(N, dtype=np.int64) * 4_000_000
    s = np.arange(N) / 250.0
    q = np.stack([0.8 * np.sin(0.05 * s * (j + 1) + j) for j in range(6)], axis=1)
    q = np.round(q / (2 * np.pi / 2**17)) * (2 * np.pi / 2**17)  # 17-bit encoders
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "stream.mcap"
        write_campaign(path, {META_CAMPAIGN: {"system": "none"}}, (t_ns, q, [f"J{i}" for i in range(1, 7)]), [])
        size = path.stat().st_size
        best = np.inf
        for _ in range(3):
            t = time.perf_counter()
            stream = joint_stream(read_recording(path))
            best = min(best, time.perf_counter() - t)
        assert len(stream) == N and np.allclose(stream.q, q, atol=1e-9)
    print(f"samples {N}, file {size / 1e6:.1f} MB, ingest {best:.3f} s → {N / best / 1e6:.2f} M samples/s")


if __name__ == "__main__":
    main()
