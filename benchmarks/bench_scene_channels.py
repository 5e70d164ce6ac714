"""Benchmark: what the ROS / Foxglove channels (/tf, /robot_description; `pipeline.recording.scene`)
cost a recording — file size and time to write, with and without them, on the default arc-welder
campaign (16 min, 242 761 encoder samples, 100 contacts), and the time to build the /tf messages alone.

Run: .venv/bin/python benchmarks/bench_scene_channels.py
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from pipeline.recording import scene, writer


def simulate(out: Path, with_scene: bool) -> tuple[int, float]:
    """(bytes, seconds) of `robocal simulate arc-welder --out out` in this process."""
    import sys

    from pipeline.cli import main

    real, argv = scene.scene_events, sys.argv
    if not with_scene:
        scene.scene_events = lambda *a, **k: []
    sys.argv = ["robocal", "simulate", "arc-welder", "--out", str(out)]
    t = time.perf_counter()
    try:
        main()
    except SystemExit as e:
        assert not e.code, f"simulate exited {e.code}"
    finally:
        dt = time.perf_counter() - t
        scene.scene_events, sys.argv = real, argv
    return out.stat().st_size, dt


def main() -> None:
    assert writer.RecordingWriter  # the writer that adds the channels
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        simulate(d / "warm.mcap", False)  # imports and caches out of the measurement
        n0, t0 = simulate(d / "plain.mcap", False)
        n1, t1 = simulate(d / "scene.mcap", True)
        from pipeline.ingest.streams import joint_stream
        from pipeline.recording.reader import read_recording

        rec = read_recording(d / "plain.mcap")
        js = joint_stream(rec)
        t = time.perf_counter()
        events = scene.scene_events(rec.metadata, (js.t_ns, js.q))
        build = time.perf_counter() - t
    n_tf = sum(1 for _, topic, _ in events if topic == scene.TF_TOPIC)
    print(f"arc-welder campaign, {js.t_ns.size} encoder samples: {n_tf} /tf messages at {scene.RATE_HZ:g} Hz")
    print(f"file: {n0 / 1e6:.2f} MB without, {n1 / 1e6:.2f} MB with the scene channels (+{(n1 / n0 - 1) * 100:.0f} %)")
    print(f"simulate: {t0:.1f} s without, {t1:.1f} s with; building the messages alone {build:.1f} s")


if __name__ == "__main__":
    main()
