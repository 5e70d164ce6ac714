"""The scanner's rerun view writes a loadable .rrd."""

import numpy as np

from pipeline.identify.least_squares import fit
from pipeline.simulate import scorbot_scanner as sim
from pipeline.systems import scorbot_scanner as sc
from pipeline.visualize.scanner import log_system


def test_log_system_writes_rrd(tmp_path):
    arm = sc.nominal_arm()
    res, table = sim.simulate_in_memory(arm, arm, sc.reference_scanner(), sim.Campaign(seed=0), sim.Noise())
    table["timestamp_ns"] = res.obs_t_ns[table["pose"]]
    m = sc.ScannerModel(arm=arm)
    f = fit(m, table)
    stripes = [(o.q, o.stripe_px) for o in res.observations]
    out = tmp_path / "scan.rrd"
    log_system(out, m, table, f.nominal, f.x, stripes=stripes)
    assert out.stat().st_size > 1000
    assert out.read_bytes()[:3] == b"RRF"  # rerun's file magic
    assert np.isfinite(f.rms_after)
