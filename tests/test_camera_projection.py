"""The generic camera's projection against OpenCV's own (cv2.projectPoints, cv2.fisheye.projectPoints)
on random inputs, and its analytic Jacobians against finite differences."""

import cv2
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.camera.projection import FISHEYE, PINHOLE, camera_matrix, intrinsic_names, project


def _case(seed: int, model: str, nd: int):
    rng = np.random.default_rng(seed)
    k = np.r_[rng.uniform(400, 1500, 2), rng.uniform(200, 900, 2)]
    if model == PINHOLE:
        d = np.r_[rng.uniform(-0.3, 0.3, 2), rng.uniform(-0.01, 0.01, 2), rng.uniform(-0.1, 0.1, 1),
                  rng.uniform(0, 0.2, 3)][:nd]
    else:
        d = rng.uniform(-0.05, 0.05, 4)
    P = np.c_[rng.uniform(-0.4, 0.4, (30, 2)), rng.uniform(0.5, 2.0, 30)]
    return np.r_[k, d], P


models = st.sampled_from([(PINHOLE, 4), (PINHOLE, 5), (PINHOLE, 8), (FISHEYE, 4)])


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31), models)
def test_projection_matches_opencv(seed, mn):
    model, nd = mn
    k, P = _case(seed, model, nd)
    uv = project(k, P, model)
    K, d = camera_matrix(k), k[4:]
    if model == PINHOLE:
        ref, _ = cv2.projectPoints(P, np.zeros(3), np.zeros(3), K, d)
    else:
        ref, _ = cv2.fisheye.projectPoints(P[:, None, :], np.zeros(3), np.zeros(3), K, d)
    np.testing.assert_allclose(uv, ref.reshape(-1, 2), rtol=0, atol=1e-6)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31), models)
def test_jacobians_match_finite_differences(seed, mn):
    model, nd = mn
    k, P = _case(seed, model, nd)
    uv, Jk, JP = project(k, P, model, jac=True)
    assert Jk.shape == (len(P), 2, 4 + nd) and len(intrinsic_names(model, nd)) == 4 + nd
    for j in range(k.size):
        h = 1e-6 * max(1.0, abs(k[j]))
        kp, km = k.copy(), k.copy()
        kp[j] += h
        km[j] -= h
        fd = (project(kp, P, model) - project(km, P, model)) / (2 * h)
        np.testing.assert_allclose(Jk[:, :, j], fd, rtol=1e-5, atol=1e-4)
    for a in range(3):
        Pp, Pm = P.copy(), P.copy()
        Pp[:, a] += 1e-7
        Pm[:, a] -= 1e-7
        fd = (project(k, Pp, model) - project(k, Pm, model)) / 2e-7
        np.testing.assert_allclose(JP[:, :, a], fd, rtol=1e-5, atol=1e-2)


def test_fisheye_on_the_optical_axis():
    """θd/r → 1 at r = 0: a point on the axis lands on the principal point with finite derivatives."""
    k = np.array([800.0, 810.0, 320.0, 240.0, 0.1, -0.02, 0.01, 0.0])
    P = np.array([[0.0, 0.0, 1.0], [1e-12, 0.0, 1.0]])
    uv, Jk, JP = project(k, P, FISHEYE, jac=True)
    np.testing.assert_allclose(uv, [[320, 240], [320, 240]], atol=1e-6)
    assert np.all(np.isfinite(Jk)) and np.all(np.isfinite(JP))
    np.testing.assert_allclose(JP[0, :, :2], np.diag([800.0, 810.0]), rtol=1e-9)
