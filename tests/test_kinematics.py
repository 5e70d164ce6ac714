"""Serial-arm kinematics: forward kinematics against an independent composition of 4×4
transforms, analytic Jacobians against finite differences, model JSON round trip."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from pipeline.models import serial_arm as sa
from pipeline.models.transforms import hrot, trans
from pipeline.recording.schemas import schema
from pipeline.systems.arc_welder import nominal_arm, reference_truth

P = 42
finite = st.floats(-1.0, 1.0, allow_nan=False)


def composed(x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Seed 000 eqs. 1–5 written out as a plain product of homogeneous matrices."""
    T = trans(*x[0:3]) @ hrot("z", x[3]) @ hrot("x", x[4]) @ hrot("y", x[5])
    for i in range(6):
        th, d, a, al, be = x[6 + 5 * i: 11 + 5 * i]
        T = T @ hrot("z", q[i] + th) @ trans(a, 0, d) @ hrot("x", al) @ hrot("y", be)
    return T @ trans(*x[36:39]) @ hrot("z", x[39]) @ hrot("y", x[40]) @ hrot("x", x[41])


@settings(max_examples=40, deadline=None)
@given(dx=arrays(float, P, elements=finite), q=arrays(float, (5, 6), elements=st.floats(-3.1, 3.1)))
def test_forward_matches_independent_composition(dx, q):
    x = reference_truth().vector() + 0.05 * dx
    R, p = sa.forward(x, q)
    T = np.array([composed(x, qi) for qi in q])
    np.testing.assert_allclose(p, T[:, :3, 3], atol=1e-12)
    np.testing.assert_allclose(R, T[:, :3, :3], atol=1e-12)
    F = sa.frames(x, q)
    np.testing.assert_allclose(F[:, -1], T, atol=1e-12)


@settings(max_examples=25, deadline=None)
@given(dx=arrays(float, P, elements=finite), q=arrays(float, (4, 6), elements=st.floats(-3.1, 3.1)))
def test_parameter_jacobian_matches_finite_differences(dx, q):
    x = nominal_arm().vector() + 0.05 * dx
    _, J = sa.tip_jacobian(x, q)
    h = 1e-6
    E = np.eye(P) * h
    fd = np.stack([(sa.tip_position(x + E[k], q) - sa.tip_position(x - E[k], q)) / (2 * h) for k in range(P)], -1)
    np.testing.assert_allclose(J, fd, atol=1e-8)


def test_joint_jacobian_matches_finite_differences():
    x = reference_truth().vector()
    q = np.random.default_rng(0).uniform(-2, 2, (6, 6))
    _, J = sa.joint_jacobian(x, q)
    h = 1e-6
    fd = np.stack([(sa.tip_position(x, q + h * e) - sa.tip_position(x, q - h * e)) / (2 * h) for e in np.eye(6)], -1)
    np.testing.assert_allclose(J, fd, atol=1e-8)


def test_tool_orientation_does_not_move_a_point_tool_tip():
    x = reference_truth().vector()
    _, J = sa.tip_jacobian(x, np.zeros((3, 6)))
    assert np.all(J[:, :, 39:] == 0)


def test_model_json_round_trip_and_schema():
    arm = reference_truth()
    d = arm.to_dict()
    jsonschema.validate(d, schema("robot_model"))
    again = sa.SerialArm.from_dict(json.loads(json.dumps(d)))
    assert again == arm
    np.testing.assert_array_equal(again.vector(), arm.vector())
    assert arm.with_vector(arm.vector()) == arm
