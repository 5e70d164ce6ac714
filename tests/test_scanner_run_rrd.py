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
    # the calibrated camera and its frustum at each pose; the SCORBOT drawn from its model, nominal and calibrated
    assert {"world/scanner/camera", "world/robot/calibrated/links", "world/robot/nominal/links"} <= set(rows)
    # each camera pose sees its corners' calibrated reconstructions in front of it, on its laser plane
    import json

    import numpy as np

    from pipeline.models import camera as cam
    from pipeline.systems.registry import detect
    from test_rerun_rrd import _read

    got = _read(tmp_path / "run" / "run.rrd")["world/scanner/camera"]
    R = np.array(got["rows"]["Transform3D:mat3x3"], float).reshape(-1, 3, 3).transpose(0, 2, 1)  # column-major
    t = np.array(got["rows"]["Transform3D:translation"], float).reshape(-1, 3)
    when = np.array(got["index"]["time"], np.int64)
    rec = read_recording(BUNDLED)
    model, table = detect(rec).load(rec)
    x = np.array(json.loads((tmp_path / "run" / "identify" / "fit.json").read_text())["x"])
    P = model.points(x, table)[0]
    n, d = cam.laser_plane(x[:cam.N_SCANNER])
    for k in range(len(when)):
        rows_k = np.flatnonzero(np.asarray(table["timestamp_ns"]) == when[k])  # the pose's corners
        assert rows_k.size > 0
        pc = (P[rows_k] - t[k]) @ R[k]  # into {C}
        assert np.all(pc[:, 2] > 0.05) and np.allclose(pc @ n, d, atol=1e-7), k
