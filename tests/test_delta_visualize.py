"""The Delta rerun hook writes a readable .rrd with the robot, measured and predicted points."""

from __future__ import annotations

import numpy as np
import rerun as rr

from pipeline.identify.least_squares import fit
from pipeline.models.delta import Delta
from pipeline.simulate import delta_tracker as sim
from pipeline.systems.delta_tracker import TrackerModel
from pipeline.visualize.delta import log_system, robot_strips, to_tracker


def test_log_system_writes_an_rrd(tmp_path):
    s = sim.simulate(Delta(), sim.random_truth(np.random.default_rng(3)), sim.Campaign(seed=3))
    table = {"joint_positions": s.q, "point": s.point_t, "timestamp_ns": s.t_ns}
    model = TrackerModel()
    f = fit(model, table)
    # the calibrated reflector lands on the measured points in the tracker frame
    pred = to_tracker(model, f.x, model.reflector(f.x, s.q))
    assert np.sqrt(np.mean((pred - s.point_t) ** 2)) < 5e-5
    strips = robot_strips(model, f.x, s.q[:2])
    assert len(strips) == 10 and strips[1].shape == (3, 3)
    # an upper arm is l1 long
    assert abs(np.linalg.norm(strips[1][1] - strips[1][0]) - (Delta().l1 + f.x[4])) < 1e-9
    rec = rr.RecordingStream("robocal-delta-test")
    path = tmp_path / "delta.rrd"
    rec.save(path)
    log_system(rec, model, table, f.nominal, f.x)
    rec.flush()
    rec.disconnect()
    assert path.stat().st_size > 2000
