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
