"""The independent generators share no robocal code: importing them (and the test support they use)
in a fresh interpreter loads no `pipeline` module.  (`independent_touch` is the stated exception: it
reads the arm's and jig's numbers from `pipeline.systems` / `pipeline.models.jig` and builds the
diagnosis table with `pipeline.diagnose.adapters.touch_table`; see its docstring.)"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent
INDEPENDENT = ("independent_arm", "independent_drive", "independent_recording", "r6_robot", "stream_support")


def test_independent_generators_import_no_robocal_code():
    code = ("import sys; " + "; ".join(f"import {m}" for m in INDEPENDENT) +
            "; print(sorted(m for m in sys.modules if m.split('.')[0] == 'pipeline'))")
    r = subprocess.run([sys.executable, "-c", code], cwd=TESTS, capture_output=True, text=True, timeout=120,
                       env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(TESTS)})
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]", r.stdout
