"""The independent generators share no robocal code: importing them (and the test support they use) in a fresh
interpreter loads no `pipeline` module — the touch generators included (`independent_touch`, `independent_search`:
their own jig drawing, `independent_jig`; only `independent_touch.default_arms` reads the arm's numbers from
`pipeline.systems` when called).  What they log enters the product as a recording does: the diagnosis table built
in memory from a campaign (`touch_ingest.diagnosis_table`) is the one `from_recording` builds from the same
campaign written to MCAP by the generator's own writer, and the generator's jig is the product's block."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

TESTS = Path(__file__).resolve().parent
INDEPENDENT = ("independent_arm", "independent_drive", "independent_recording", "r6_robot", "stream_support",
               "independent_jig", "independent_touch", "independent_search", "independent_campaign_file")


def test_independent_generators_import_no_robocal_code():
    code = ("import sys; " + "; ".join(f"import {m}" for m in INDEPENDENT) +
            "; print(sorted(m for m in sys.modules if m.split('.')[0] == 'pipeline'))")
    r = subprocess.run([sys.executable, "-c", code], cwd=TESTS, capture_output=True, text=True, timeout=120,
                       env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(TESTS)})
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]", r.stdout


def test_the_generators_block_is_the_products_stepped_block():
    import independent_jig as ij

    from pipeline.models.jig import stepped_block

    mine, theirs = ij.stepped_block(), stepped_block()
    assert mine.name == theirs.name
    assert [(f.id, f.axis, f.coordinate, f.normal_sign, f.extent) for f in mine.faces] == \
        [(f.id, f.axis, f.coordinate, f.normal_sign, tuple(map(tuple, f.extent))) for f in theirs.faces]


def test_a_random_search_campaign_ingests_alike_from_memory_and_from_its_mcap(tmp_path):
    """The campaign of random searches, mixed payloads and a noisy servo stream: written by the generator's own
    MCAP writer and read by `from_recording`, every diagnosis column equals the in-memory table's."""
    import independent_recording as ir
    import independent_search as isr
    import independent_touch as it
    from touch_ingest import diagnosis_table

    from pipeline.diagnose.adapters.touch_table import from_recording
    from pipeline.models.jig import stepped_block
    from pipeline.recording.reader import read_recording
    from pipeline.systems import arc_welder as aw

    nom, tru = it.default_arms()
    sc = isr.plan(tru, m=24, seed=3)
    c = isr.run(nom, tru, sc, (it.Effect("backlash", 1e-3, {"joint": 2}),), seed=3, n=24, stream_noise_counts=1.0)
    path = tmp_path / "random.mcap"
    ir.write_recording(path, c, aw.nominal_arm().to_dict(), stepped_block().to_dict())
    _, tab, info = from_recording(read_recording(path))
    mine = diagnosis_table(c)
    assert info["payload_from"] == "events"
    assert len(set(mine["payload_kg"])) > 1  # mixed payloads
    for k, v in mine.items():
        a, b = np.asarray(v), np.asarray(tab[k])
        if a.dtype.kind in "fc":  # the writer keeps positions to 1 nrad: ≤ 2.5e-8 rad/s over a 40 ms window
            np.testing.assert_allclose(b, a, rtol=0, atol=5e-8, err_msg=k)
        else:
            assert np.array_equal(a, b), k
