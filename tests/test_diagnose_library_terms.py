"""The library's physics terms as identification will use them: importable alone, each term's value
B·θ consistent with its signature in the touch residual, joint terms' signatures equal to the finite
difference of the tip position, and the lens terms' Jacobian against finite differences."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.diagnose.adapters.touch_table import from_recording
from pipeline.diagnose.library.lens import lens_excess, lens_excess_jacobian
from pipeline.diagnose.library.term import axis_rows, signature
from pipeline.diagnose.library.touch import touch_library
from pipeline.models import serial_arm
from pipeline.recording.reader import read_recording

ROOT = Path(__file__).resolve().parents[1]
RECORDING = ROOT / "recordings" / "arc-welder-touch.mcap"


def test_the_library_imports_none_of_the_diagnosis_machinery():
    code = ("import sys, pipeline.diagnose.library.touch, pipeline.diagnose.library.lens, "
            "pipeline.diagnose.library.urdf_gravity\n"
            "print(sorted(m for m in sys.modules if m.startswith('pipeline.diagnose.') "
            "and not m.startswith('pipeline.diagnose.library')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"


def test_every_touch_term_value_matches_its_signature_and_joint_terms_the_tip_motion():
    model, tab, _ = from_recording(read_recording(RECORDING))
    arm = model.arm
    x = arm.vector()
    q = np.asarray(tab["joint_positions"], float)
    rows, ax = axis_rows(tab)
    _, Jq = serial_arm.joint_jacobian(x, q)
    rng = np.random.default_rng(0)
    lib = touch_library(arm, tab)
    assert len({e.where for e in lib}) == 3 and len(lib) > 40
    for e in lib:
        theta = rng.standard_normal(e.k) * e.plausible
        S = signature(e, arm, x, tab)
        v = e.value(arm, x, tab, theta)
        assert np.array_equal(e.jacobian(arm, x, tab), e.basis(arm, x, tab))
        if e.where == "joint":
            assert v.shape == q.shape
            np.testing.assert_allclose(S @ theta, np.einsum("nj,nj->n", Jq[rows, ax], v), rtol=1e-9, atol=1e-15)
            # the true joint angle is the reading plus δq: to first order the tip moves by S·θ (m)
            h = 1e-3
            dp = (serial_arm.tip_position(x, q + h * v) - serial_arm.tip_position(x, q - h * v)) / (2 * h)
            np.testing.assert_allclose(S @ theta, dp[rows, ax], rtol=1e-5, atol=1e-6 * e.plausible, err_msg=e.label)
        elif e.where == "tip":
            assert v.shape == (q.shape[0], 3)
            np.testing.assert_allclose(S @ theta, v[rows, ax], rtol=1e-12, atol=1e-18, err_msg=e.label)
        else:
            np.testing.assert_allclose(S @ theta, v, rtol=1e-12, err_msg=e.label)


@settings(max_examples=40, deadline=None)
@given(st.floats(-5e4, 5e4), st.floats(-5e-2, 5e-2), st.floats(-5e-2, 5e-2),
       st.lists(st.floats(-3e-3, 3e-3), min_size=2, max_size=2))
def test_lens_excess_jacobian_against_finite_differences(k2, p1, p2, uv):
    ut, vt = np.array([uv[0]]), np.array([uv[1]])
    J = lens_excess_jacobian(ut, vt, k2, p1, p2)[0]
    h = 1e-7
    for c, (du, dv) in enumerate(((h, 0.0), (0.0, h))):
        up = np.array(lens_excess(ut + du, vt + dv, k2, p1, p2))[:, 0]
        um = np.array(lens_excess(ut - du, vt - dv, k2, p1, p2))[:, 0]
        np.testing.assert_allclose((up - um) / (2 * h), J[:, c], rtol=1e-5, atol=1e-9)
