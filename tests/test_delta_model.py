"""Delta robot kinematics (seed 003): analytic FK/IK with β', full model, Jacobians, registration."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from pipeline.models import delta as dm
from pipeline.models.delta import Delta
from pipeline.systems.delta_tracker import TrackerModel, register, registration_matrix

D = Delta()
CENTER = np.array([0.0, 0.0, -0.75])


def _workspace(rng: np.random.Generator, n: int) -> np.ndarray:
    return CENTER + rng.uniform(-1, 1, (n, 3)) * [0.2, 0.2, 0.08]


def _fd(f, x: np.ndarray, h: float = 1e-7) -> np.ndarray:
    return np.stack([(f(x + e) - f(x - e)) / (2 * h) for e in np.eye(x.size) * h], axis=-1)


seeds = st.integers(0, 2**32 - 1)


@settings(max_examples=30, deadline=None)
@given(seeds)
def test_forward_inverse_round_trip(seed):
    rng = np.random.default_rng(seed)
    beta = rng.normal(0, 1e-3, 27)
    p = _workspace(rng, 50)
    theta, ok = dm.inverse(D, beta, p)
    assert ok.all()
    p2, ok2 = dm.forward(D, beta, theta)
    assert ok2.all()
    np.testing.assert_allclose(p2, p, atol=1e-10)
    # every leg closes: |rod| = l2 + Δl2
    r = np.linalg.norm(dm.rods(D, beta, theta, p2), axis=-1)
    np.testing.assert_allclose(r, np.broadcast_to(D.l2 + beta.reshape(3, 9)[:, 5], r.shape), atol=1e-12)


def test_physical_root_is_below_the_elbows():
    theta, _ = dm.inverse(D, np.zeros(27), CENTER[None])
    p, _ = dm.forward(D, np.zeros(27), theta)
    elbows = dm.geometry(D, np.zeros(27), theta, p)["elbow"]
    assert p[0, 2] < elbows[0, :, 2].min()
    np.testing.assert_allclose(p[0], CENTER, atol=1e-12)


def test_no_real_root_is_flagged():
    theta = np.array([[-1.0297, -2.1974, -0.3120], [-0.3, -0.3, -0.3]])
    p, ok = dm.forward(D, np.zeros(27), theta)
    assert ok.tolist() == [False, True]


@settings(max_examples=15, deadline=None)
@given(seeds)
def test_simplified_jacobian_matches_finite_differences(seed):
    rng = np.random.default_rng(seed)
    beta = rng.normal(0, 1e-3, 27)
    theta, _ = dm.inverse(D, beta, _workspace(rng, 20))
    p, _ = dm.forward(D, beta, theta)
    J = dm.forward_jacobian(D, beta, theta, p)
    Jn = _fd(lambda b: dm.forward(D, b, theta)[0], beta)
    np.testing.assert_allclose(J, Jn, atol=2e-7 * np.abs(J).max())


def test_full_model_reduces_to_the_simplified_one():
    rng = np.random.default_rng(1)
    B = np.zeros((3, 12))
    B[:, :9] = rng.normal(0, 1e-3, (3, 9))
    theta, _ = dm.inverse(D, B[:, :9].ravel(), _workspace(rng, 30))
    p, R, ok = dm.full_forward(D, B.ravel(), theta)
    assert ok.all()
    np.testing.assert_allclose(p, dm.forward(D, B[:, :9].ravel(), theta)[0], atol=1e-12)
    np.testing.assert_allclose(R, np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    # axis-direction errors and unequal rods tilt the platform and move P
    B[:, 9:11] = 3e-3
    B[:, 11] = 3e-4
    p2, R2, ok2 = dm.full_forward(D, B.ravel(), theta)
    assert ok2.all()
    assert np.abs(p2 - p).max() > 1e-4 and Rotation.from_matrix(R2).magnitude().max() > 1e-3


@settings(max_examples=8, deadline=None)
@given(seeds)
def test_full_jacobian_matches_finite_differences(seed):
    rng = np.random.default_rng(seed)
    x = rng.normal(0, 1e-3, 36)
    theta, _ = dm.inverse(D, np.zeros(27), _workspace(rng, 10))
    off = np.array([0.0, 0.0, -0.05])
    p, R, ok = dm.full_forward(D, x, theta)
    assert ok.all()
    J, _ = dm.full_jacobian(D, x, theta, p, R, off)

    def reflector(b):
        pp, RR, _ = dm.full_forward(D, b, theta)
        return pp + RR @ off

    Jn = _fd(reflector, x)
    np.testing.assert_allclose(J, Jn, atol=2e-7 * np.abs(J).max())


@pytest.mark.parametrize("variant", ["simplified", "extended"])
def test_measurement_model_jacobians_match_finite_differences(variant):
    rng = np.random.default_rng(7)
    m = TrackerModel(variant=variant)
    theta, _ = dm.inverse(D, np.zeros(27), _workspace(rng, 15))
    table = {"joint_positions": theta, "point": rng.normal(0, 1, (15, 3))}
    x = m.nominal() + rng.normal(0, 1e-3, m.nominal().size)
    x[m.n_beta: m.n_beta + 6] = [1.5, -1.0, -1.3, 0.6, 0.02, -0.01]
    np.testing.assert_allclose(m.jacobian(x, table), _fd(lambda z: m.residuals(z, table), x), atol=1e-6)
    np.testing.assert_allclose(m.points(x, table)[1], _fd(lambda z: m.points(z, table)[0], x), atol=1e-6)
    assert m.residuals(x, table).shape == (15, 3)
    assert len(m.parameter_names()) == len(m.parameter_units()) == x.size == (43 if variant == "extended" else 34)


@settings(max_examples=25, deadline=None)
@given(seeds, st.integers(4, 40))
def test_registration_recovers_a_rigid_transform(seed, n):
    rng = np.random.default_rng(seed)
    reg = np.concatenate([rng.uniform(-3, 3, 3), rng.uniform(-np.pi, np.pi, 1), rng.uniform(-1.2, 1.2, 2)])
    R, t = registration_matrix(reg)
    p_a = _workspace(rng, n)
    p_t = (p_a - t) @ R  # Rᵀ(p_a − t)
    est = register(p_a, p_t)
    R2, t2 = registration_matrix(est)
    np.testing.assert_allclose(R2, R, atol=1e-9)
    np.testing.assert_allclose(t2, t, atol=1e-9)


def test_registration_needs_four_non_collinear_points():
    p = _workspace(np.random.default_rng(0), 3)
    with pytest.raises(ValueError, match="at least 4"):
        register(p, p)
    line = np.outer(np.linspace(0, 1, 6), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="collinear"):
        register(line, line)


def test_model_json_round_trip():
    d = Delta(a=0.21, l2=0.81)
    assert Delta.from_dict(d.to_dict()) == d
    doc = TrackerModel(d).describe(TrackerModel(d).nominal())
    assert doc["kind"] == "delta" and len(doc["legs"]) == 3 and Delta.from_dict(doc) == d
    with pytest.raises(ValueError):
        Delta.from_dict({"kind": "serial_arm", "name": "x"})
