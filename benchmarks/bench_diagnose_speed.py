"""Benchmark: time to diagnose a 300-contact arc-welder recording (target < 1 s).

Run: .venv/bin/python benchmarks/bench_diagnose_speed.py [--default-blas]
(`--default-blas`: the diagnosis with the BLAS's own thread count instead of `pipeline.blas.one_thread`,
the comparison behind that module's docstring.)
Simulates a clean campaign and one with two effects (payload 0/6 kg, three search speeds), then times (best of 3)
- the diagnosis core (geometric fit, gating, selection, confirmation, lack of fit);
- the `diagnose` stage of `robocal run` (`pipeline.diagnose.stage.run` after ingest): the recording
  less its encoder stream (ingest's `messages.parquet`), the stream from ingest's `encoder.parquet`,
  motion context, diagnosis, diagnosis.json;
- standalone `robocal diagnose REC.mcap`: the same, decoding the MCAP's JSON encoder batches
  itself (≈ 0.8 M samples here; ingest pays this once in a run);
and, per phase (best of 3 each): reading the MCAP, decoding the encoder stream, the stage's
reading of ingest's artefacts (`messages.parquet`, `encoder.parquet`), the diagnosis table
(contacts + motion context), the core, writing diagnosis.json.  Wall-clock times, and the CPU
time of core / stage / standalone (on a shared box the wall time includes waiting for a core).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

from pipeline.diagnose import diagnose
from pipeline.diagnose.stage import diagnose_recording, settings_of
from pipeline.diagnose.adapters.touch_table import from_recording
from pipeline.ingest.context import last_motion_sign
from pipeline.ingest.streams import JOINT_STATE, joint_stream
from pipeline.recording.reader import read_recording
from pipeline.diagnose import stage as diagnose_stage
from pipeline.stages.artefacts import write_json
from pipeline.stages.ingest import load_system, read_encoder
from pipeline.stages.runner import run_pipeline


CASES = {"clean": [], "two effects": ["--effect", "backlash=5e-4@J3", "--effect", "joint_compliance=1e-5@J2"]}


def main() -> None:
    if "--default-blas" in sys.argv[1:]:
        import contextlib

        import pipeline.diagnose.method as dd

        dd.one_thread = contextlib.nullcontext
        print("BLAS threads: library default (not limited to one)")
    for label, extra in CASES.items():
        one(label, extra)


def best(f, setup=lambda: None, n: int = 3) -> float:
    """Best of n wall-clock times of f(setup()), s (the set-up untimed)."""
    ts = []
    for _ in range(n):
        a = setup()
        t = time.perf_counter()
        f(a)
        ts.append(time.perf_counter() - t)
    return min(ts)


def one(label: str, extra: list[str]) -> None:
    with tempfile.TemporaryDirectory() as d:
        rec_path = Path(d) / "rec.mcap"
        subprocess.run([str(Path(sys.executable).parent / "robocal"), "simulate", "arc-welder", "--out", str(rec_path),
                        "--contacts", "300", "--payloads", "0,6", "--search-speeds", "0.005,0.01,0.02", "--seed", "2", *extra],
                       check=True, capture_output=True)
        rec = read_recording(rec_path)
        model, table, info = from_recording(rec)
        run_pipeline(rec_path, Path(d) / "run", stages=["ingest"])
        stream = joint_stream(rec)
        doc = diagnose(model, table, jig_tolerance_m=info.get("jig_tolerance_m", 2e-5))
        run_dir = Path(d) / "run"
        took = {"read MCAP": best(lambda _: read_recording(rec_path)),
                "decode stream": best(joint_stream, lambda: read_recording(rec_path, topics={JOINT_STATE})),
                "stage reads ingest artefacts": best(lambda _: (load_system(run_dir), read_encoder(run_dir))),
                "table": best(lambda _: from_recording(rec, stream)),
                "write diagnosis.json": best(lambda _: write_json(Path(d) / "diagnosis.json", doc))}
        lms = best(lambda _: last_motion_sign(stream.t_ns, stream.q, table["timestamp_ns"]))
        runs = {"core": lambda: diagnose(model, table, jig_tolerance_m=info.get("jig_tolerance_m", 2e-5)),
                # what `robocal run` does: writes run/diagnose/diagnosis.json
                "stage": lambda: diagnose_stage.run(run_dir, {}),
                "standalone": lambda: diagnose_recording(read_recording(rec_path), settings_of({}))}
        wall: dict[str, list[float]] = {k: [] for k in runs}
        cpu: dict[str, list[float]] = {k: [] for k in runs}
        for _ in range(3):
            for k, f in runs.items():
                t, c = time.perf_counter(), time.process_time()
                f()
                wall[k].append(time.perf_counter() - t)
                cpu[k].append(time.process_time() - c)
    w, c = ({k: min(v) for k, v in x.items()} for x in (wall, cpu))
    print(f"300 contacts, {label}: diagnosis core {w['core']:.2f} s, diagnose stage (stream from ingest) "
          f"{w['stage']:.2f} s, standalone with stream decoding {w['standalone']:.2f} s (of which the last-motion "
          f"signs over {len(stream)} samples {lms:.3f} s); "
          f"findings {[f['effect'] for f in doc['findings']]}, unexplained {doc['unexplained']}")
    print(f"  CPU time (this process, all threads; wall > CPU when the box is busy): core {c['core']:.2f} s, "
          f"stage {c['stage']:.2f} s, standalone {c['standalone']:.2f} s")
    print(f"  phases (wall): {', '.join(f'{k} {v:.3f} s' for k, v in took.items())}, core {w['core']:.3f} s")


if __name__ == "__main__":
    main()
