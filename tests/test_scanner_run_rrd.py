"""A pipeline run of the bundled scanner recording shows the stripe in the image and in 3-D."""

from __future__ import annotations

from pathlib import Path
from rerun.chunk import RrdReader

from pipeline.recording.reader import read_recording
from pipeline.stages.runner import run_pipeline

BUNDLED = Path(__file__).resolve().parent.parent / "recordings" / "scorbot-scanner.mcap"


def test_run_rrd_has_the_stripe_in_image_and_3d(tmp_path):
    run_pipeline(BUNDLED, tmp_path / "run")
    rows: dict[str, int] = {}
    image_points = 0
    for chunk in RrdReader(tmp_path / "run" / "run.rrd").stream():
        path = chunk.entity_path.lstrip("/")
        rows[path] = rows.get(path, 0) + chunk.to_record_batch().num_rows
        if path == "image/stripe":
            b = chunk.to_record_batch()
            col = next(n for n in b.schema.names if n.endswith("LineStrips2D:strips"))
            image_points += sum(len(strip) for cell in b.column(col).to_pylist() for strip in cell)
    observations = read_recording(BUNDLED).messages["/scanner/stripe"]
    assert rows.get("image/stripe") == len(observations)  # one stripe per observation
    assert rows.get("world/scanner/stripe") == len(observations)
    assert image_points == sum(len(m["stripe_px"]) for m in observations)
    assert {"world/scanner/corners", "world/scanner/reconstructed/before", "world/scanner/reconstructed/after"} <= set(rows)
