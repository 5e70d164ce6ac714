"""The rank re-test at each solution (seed 000, eq. 57) frees only what the data determine.

A UR10 (the real URDF of ../shared/real-data) with N(0, 4 mm / 8 mrad) joint-origin errors,
100 points at random configurations, the point on the last joint's axis nominally: at the first
solution the tool offset is a few mm, which makes the last joints' origin rotations formally
identifiable through a 4 mm lever.  Freed, they moved by radians and the fit left the true
robot (seed 2: 9 rad on wrist_3.rx, 901 of 1 000 compensation targets unreachable; seed 10: a
3.4 mm local minimum).  They are freed only when their σ is below their prior σ."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.accuracy.prior import prior_sigma
from pipeline.compensate.serial import ChainKinematics, compensate
from pipeline.identify.least_squares import FitOptions, fit, weakly_freed
from pipeline.measurements.point import PointModel
from pipeline.models import urdf
from pipeline.models.urdf_arm import UrdfArm
from pipeline.plan.urdf_robot import configurations
from pipeline.simulate.urdf_robot import campaign, random_truth
from test_urdf_import import REAL, needs_real


@needs_real
@pytest.mark.parametrize("seed", [2, 10])
def test_ur10_fit_stays_with_the_true_robot(seed):
    arm = UrdfArm(urdf.read(REAL / "figaroh_ur10_pose" / "ur10_robot.urdf", "base_link", "wrist_3_link"))
    model = PointModel(arm)
    x_true = random_truth(model, np.random.default_rng(seed), 4e-3, 8e-3, registration=False)
    table, _ = campaign(model, x_true, 100, seed, "point", noise_m=5e-5)
    f = fit(model, table, FitOptions(before=False))
    assert f.rms_after < 1.2 * 5e-5  # at the noise floor (50 µm per axis); seed 10 stopped at 3.4 mm
    prior = prior_sigma(model)[0]
    assert np.all(f.std[f.free] < prior[f.free])  # every free parameter determined better than its prior
    weak = [n for i, n in enumerate(f.names) if "prior" in f.identifiability.reasons.get(i, "")]
    assert any(n.startswith("wrist_3_joint.r") for n in weak), f.identifiability.reasons
    # the calibrated model predicts the true robot at new configurations to within its σ
    q = configurations(arm, 300, 10_000 + seed)
    p_true, _ = model.points(x_true, {"joint_positions": q})
    p_cal, Jp = model.points(f.x, {"joint_positions": q})
    Jp = Jp[:, :, f.free]
    pred = np.sqrt(np.mean(np.einsum("nip,pq,niq->n", Jp, f.cov, Jp)))
    true = np.sqrt(np.mean(np.sum((p_cal - p_true) ** 2, axis=1)))
    assert true < 2.5 * pred and true < 1e-4, (true, pred)
    # and a program compensated with it reaches its targets on the true robot (seed 2 before: 901 of
    # 1 000 targets unreachable — its radians of wrist rotation broke the inverse kinematics)
    kin = ChainKinematics.of(arm)
    x0 = model.nominal()
    R, p = kin.pose(x0, q)
    c = compensate(kin, x0, f.x, p, R, np.zeros((1, kin.n_joints)), hint=q)
    ok = c.status == "ok"
    assert ok.mean() > 0.7, {s: int((c.status == s).sum()) for s in set(c.status)}
    after = np.linalg.norm(kin.pose(x_true, c.q[ok])[1] - p[ok], axis=1)
    assert np.sqrt(np.mean(after**2)) < 1e-4


def test_weakly_freed_keeps_a_well_determined_parameter_and_drops_a_weak_one():
    """On a 2-parameter linear model: a column of 1 m per unit is determined far better than
    its prior; a column of 1 µm per unit is not."""

    class Line:
        def parameter_names(self):
            return ["J1.a", "J1.b"]

        def parameter_units(self):
            return ["m", "m"]

        def nominal(self):
            return np.zeros(2)

        def residuals(self, x, data):
            return data["A"] @ x - data["y"]

        def jacobian(self, x, data):
            return data["A"][:, None, :]

    rng = np.random.default_rng(0)
    A = np.column_stack([rng.normal(size=200), 1e-6 * rng.normal(size=200)])
    data = {"A": A, "y": A @ np.array([1e-3, 1e-3]) + rng.normal(0, 1e-5, 200)}
    before, after = np.array([False, False]), np.array([True, True])
    weak = weakly_freed(Line(), data, np.array([1e-3, 1e-3]), before, after)
    assert weak.tolist() == [False, True]
    assert not weakly_freed(Line(), data, np.array([1e-3, 1e-3]), after, after).any()  # only newly freed ones
    # the prior it judges against is the one given: a loose prior on b keeps it free
    assert not weakly_freed(Line(), data, np.array([1e-3, 1e-3]), before, after, prior=np.array([1e-3, 1e3])).any()


def test_the_identify_stage_judges_against_the_recording_s_and_the_command_line_s_priors():
    """identify's options carry each parameter's prior 1σ: the defaults, the robot model file's
    prior_sigma, then --prior (the stage's `prior` param) — as the accuracy stage uses them."""
    from pathlib import Path

    from pipeline.recording.reader import read_recording
    from pipeline.recording.schemas import META_ROBOT
    from pipeline.stages.identify import options_of
    from pipeline.systems.registry import SYSTEMS

    rec = read_recording(Path(__file__).parents[1] / "recordings" / "arc-welder-touch.mcap", topics={"/touch/contact"})
    model, _ = SYSTEMS["arc-welder"].load(rec)
    names = model.parameter_names()
    default = prior_sigma(model)[0]
    assert np.allclose(options_of({}, model, rec).prior_sigma, default)
    rec.metadata[META_ROBOT] = {**rec.metadata[META_ROBOT], "prior_sigma": {names[3]: 0.25}}
    got = options_of({"prior": {names[5]: 0.5}}, model, rec).prior_sigma
    want = default.copy()
    want[3], want[5] = 0.25, 0.5
    assert np.allclose(got, want)
