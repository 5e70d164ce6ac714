"""The seed systems are compositions of generic parts: the Delta + laser tracker is
`DeltaKinematics` + `RegisteredPointModel` (a point measured in a registered instrument frame),
and the same measurement type composes with any serial chain (a URDF arm) unchanged."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.identify.least_squares import FitOptions, fit
from pipeline.measurements import registration as rg
from pipeline.measurements.registered_point import RegisteredPointModel
from pipeline.models.delta_arm import DeltaKinematics
from pipeline.plan.urdf_robot import configurations
from pipeline.simulate.urdf_robot import random_truth
from pipeline.systems.delta_tracker import TrackerModel
from test_urdf_simulate import arm_of


def fd_jacobian(model, x, data, h=1e-7):
    cols = [(model.residuals(x + h * e, data) - model.residuals(x - h * e, data)).ravel() / (2 * h)
            for e in np.eye(x.size)]
    return np.stack(cols, -1).reshape(len(data["joint_positions"]), 3, x.size)


@pytest.mark.parametrize("variant", ["simplified", "extended"])
def test_the_delta_tracker_is_a_composition_with_exact_jacobian(variant):
    model = TrackerModel(variant=variant)
    assert isinstance(model, RegisteredPointModel) and isinstance(model.kin, DeltaKinematics)
    assert model.parameter_names()[-7:] == ["tracker.x", "tracker.y", "tracker.z", "tracker.rz", "tracker.ry",
                                            "tracker.rx", "reflector.h"]
    rng = np.random.default_rng(3)
    theta = rng.uniform(-0.3, 0.6, (12, 3))
    x = model.nominal() + rng.normal(0, 1e-3, model.nominal().size)
    data = {"joint_positions": theta, "point": rng.normal(0, 0.2, (12, 3))}
    np.testing.assert_allclose(model.jacobian(x, data), fd_jacobian(model, x, data), atol=2e-6)


@pytest.mark.parametrize("robot", ["6R", "P+6R"])
def test_a_registered_tracker_on_a_serial_arm_recovers_the_truth(robot):
    """The Delta's measurement type, unchanged, on a URDF arm: noise-free tracker points in a
    tilted, offset tracker frame → the calibrated tool point within 1 µm of the truth at new
    configurations, seen in the tracker frame (joint 1's origin and the registration share a
    rigid-motion gauge, so {A} itself is not observable)."""
    arm = arm_of(robot)
    model = RegisteredPointModel(arm, instrument="tracker", targets=(("smr.z", (0.0, 0.0, 1.0), 0.02),))
    rng = np.random.default_rng(5)
    truth = random_truth(model, rng, 2e-3, 5e-3, registration=False)
    reg = np.array([1.2, -0.4, 0.3, 0.7, 0.05, -0.08])
    truth[model.n_kin:model.n_kin + 6] = reg
    truth[-1] = 0.035
    q = configurations(arm, 80, 2)
    p_a = model.target_point(truth, q)
    R, t = rg.registration_matrix(reg)
    data = {"joint_positions": q, "point": (p_a - t) @ R}  # what the tracker reads, {T}
    base = tuple(n for n in model.parameter_names() if n.startswith("base."))  # the registration's gauge
    f = fit(model, data, FitOptions(fixed=base))
    assert np.sqrt(np.mean(f.residuals_after ** 2)) < 1e-9
    qn = configurations(arm, 200, 99)

    def in_tracker(x):
        Rx, tx = rg.registration_matrix(x[model.n_kin:model.n_kin + 6])
        return (model.target_point(x, qn) - tx) @ Rx

    assert np.linalg.norm(in_tracker(f.x) - in_tracker(truth), axis=1).max() < 1e-6


def test_the_scanner_is_a_composition():
    from pipeline.measurements.sensed_point import SensedPointModel
    from pipeline.models.serial_arm import SerialArm
    from pipeline.models.stripe_sensor import StripeSensor
    from pipeline.systems.scorbot_scanner import ScannerModel

    m = ScannerModel(joint_offsets=True)
    assert isinstance(m, SensedPointModel) and isinstance(m.arm, SerialArm) and isinstance(m.sensor, StripeSensor)
    assert m.parameter_names()[14:] == [f"J{i}.theta_offset" for i in range(1, 6)]


@pytest.mark.parametrize("robot", ["6R", "P+6R"])
def test_the_stripe_scanner_on_a_urdf_arm_has_exact_jacobians(robot):
    """The scanner's measurement type, unchanged, on a URDF arm with a prismatic joint: joint
    offsets only for the revolute joints, each mapped to its own joint; analytic = finite
    differences; the simulated corners are met exactly at the truth."""
    from pipeline.measurements.sensed_point import SensedPointModel
    from pipeline.models import camera as cam
    from pipeline.models.stripe_sensor import StripeSensor
    from pipeline.systems.scorbot_scanner import reference_scanner

    arm = arm_of(robot)
    s = reference_scanner()
    model = SensedPointModel(arm, StripeSensor(), tuple(s), joint_offsets=True)
    n_off = sum(n.endswith(".offset") for n in arm.parameter_names())
    assert len(model.parameter_names()) == 14 + n_off
    rng = np.random.default_rng(4)
    q = configurations(arm, 15, 4)
    px = np.column_stack([rng.uniform(100, 540, 15), rng.uniform(80, 400, 15)])
    x = model.nominal() + np.concatenate([np.zeros(14), rng.normal(0, 1e-3, n_off)])
    p_f = cam.camera_to_flange(s, cam.camera_points(s, px))
    R_f, t_f = model.flange(x, q)
    data = {"joint_positions": q, "pixel": px, "corner": np.einsum("nij,nj->ni", R_f, p_f) + t_f}
    assert np.abs(model.residuals(x, data)).max() < 1e-12
    J = model.jacobian(x, data)
    h = np.maximum(np.abs(x), 1e-3) * 1e-6
    fd = np.stack([(model.residuals(x + hi * e, data) - model.residuals(x - hi * e, data)) / (2 * hi)
                   for hi, e in zip(h, np.eye(x.size))], -1)
    scale = np.abs(fd).max(axis=(0, 1))  # per parameter: columns differ by orders of magnitude
    assert np.all(scale > 0)
    assert np.max(np.abs(J - fd).max(axis=(0, 1)) / scale) < 1e-5
