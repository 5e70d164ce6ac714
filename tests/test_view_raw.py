"""`robocal view REC.mcap`: a raw recording opened with a layout and the robot as built, read back
with rerun's own reader; a missing recording is a one-line error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rerun.chunk import RrdReader

from conftest import run_cli
from test_rerun_rrd import _read


def test_view_of_a_raw_urdf_recording(tmp_path):
    from test_urdf_simulate import PR6

    u = tmp_path / "r.urdf"
    u.write_text(PR6)
    rec = tmp_path / "sim.mcap"
    p = run_cli("simulate", "urdf", "--urdf", u, "--root", "base", "--tip", "flange", "--measure", "point",
                "--poses", "15", "--noise-mm", "0.02", "--out", rec)
    assert p.returncode == 0, p.stderr
    before = rec.read_bytes()
    p = run_cli("view", rec, "--print")
    assert p.returncode == 0, p.stderr
    rrd = Path(p.stdout.splitlines()[0])
    assert rrd.suffix == ".rrd" and rrd.is_file() and rec.read_bytes() == before  # the recording untouched
    got = _read(rrd)
    assert {"world/robot_nominal/joints/arm_1", "world/robot_nominal/placement", "world/instrument",
            "world/measured", "world/tips/nominal", "encoder/postures", "summary"} <= set(got)
    # the nominal robot seen through the fitted registration: its tool points within mm of the measured ones
    p0 = np.array(got["world/tips/nominal"]["static"]["Points3D:positions"])
    m = np.array(got["world/measured"]["static"]["Points3D:positions"])
    assert p0.shape == m.shape == (15, 3)
    assert np.sqrt(np.mean(np.sum((p0 - m) ** 2, axis=1))) < 0.05
    links = {e.split("/")[3] for e in got if e.startswith("world/robot_nominal/visual_geometries/")}
    assert {"torso", "a1", "a6", "flange"} <= links  # the URDF's links by name (rerun's URDF loader)
    assert len(got["world/robot_nominal/joints/arm_1"]["index"]["time"]) == 15
    r = RrdReader(rrd)
    kinds = set()
    for chunk in r.stream(store=r.blueprints()[0]):
        b = chunk.to_record_batch()
        if "ViewBlueprint:class_identifier" in b.schema.names:
            kinds |= {v for row in b.column("ViewBlueprint:class_identifier").to_pylist() for v in row}
    assert {"3D", "TimeSeries", "TextDocument"} <= kinds


def test_view_of_a_missing_recording_is_a_clear_error(tmp_path):
    p = run_cli("view", tmp_path / "nope.mcap", "--print")
    assert p.returncode == 2 and "nope.mcap" in p.stderr and "Traceback" not in p.stderr
