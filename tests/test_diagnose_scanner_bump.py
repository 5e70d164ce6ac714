"""An out-of-library bump in the SCORBOT scanner's J2 transmission: located by the
lack-of-fit scan, and not named as a library effect with confidence.

The bump (width 0.1 rad) is centred at one of the campaign's poses, so it acts on a few poses
only: a localised alternative.  The seeds are benchmark campaigns (`bench_diagnose_scanner.py`,
seeds 10000 + s) on which the former smooth test (6 Gaussian bumps per joint, grouped F, wild
cluster bootstrap) missed it: 2 mrad on seed 15, 1 mrad on seeds 5 and 8 (it located 0 of these
3, `test_the_former_smooth_test_misses_these_bumps`)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline.blas import one_thread
from pipeline.diagnose.verdict import lack_of_fit
from pipeline.diagnose.adapters import scanner as ds
from pipeline.diagnose import Settings, diagnose
from pipeline.models import camera as cam
from pipeline.simulate import scorbot_scanner as ss
from pipeline.simulate.effects import parse_effect
from pipeline.systems import scorbot_scanner as sc

ARM = sc.nominal_arm()
FAST = Settings(n_boot=8)  # the bootstrap grades confidence (without it every finding is `low`)
NO_BOOT = Settings(n_boot=0)
CASES = [(2e-3, 10_015), (1e-3, 10_005), (1e-3, 10_008)]
PLANS: dict = {}


def truth() -> np.ndarray:
    s = sc.reference_scanner()
    s[[cam.I_V0, cam.I_TH]] = sc.nominal_scanner()[[cam.I_V0, cam.I_TH]]
    return s


def campaign(seed: int, effects=()):
    c = ss.Campaign(poses=20, corners=5, seed=seed, capture_speed_rad_s=0.1)
    sim, tab = ss.simulate_in_memory(ARM, ARM, truth(), c, effects=tuple(parse_effect(e) for e in effects),
                                     plan_cache=PLANS)
    return ds.add_context(tab, sim.stream_t_ns, sim.stream_q)


def bump_run(amp: float, seed: int, settings: Settings = FAST) -> tuple[dict, float]:
    q2 = np.unique(campaign(seed)["joint_positions"][:, 1])
    centre = float(np.sort(q2)[len(q2) // 2])  # at one of the campaign's poses (as the benchmark)
    tab = campaign(seed, [f"bump={amp}@J2:{centre:.4f}"])
    model = sc.ScannerModel(arm=ARM)
    return diagnose(model, tab, adapter=ds.adapter(model, tab), settings=settings), centre


def located(doc: dict, centre: float) -> bool:
    w = doc["unexplained_where"]
    return bool(w) and w[0]["variable"] == "q_J2" and w[0]["region"][0] <= centre <= w[0]["region"][1]


def test_localised_bump_is_located_on_q_J2_and_not_named_with_confidence():
    hits = 0
    for amp, seed in CASES:
        doc, centre = bump_run(amp, seed)
        hits += located(doc, centre)
        assert not [f for f in doc["findings"] if f["confidence"] == "high"], (amp, seed)
    assert hits >= 2  # the former smooth test: 0 of 3


def test_clean_campaign_has_nothing_unexplained():
    tab = campaign(10_015)
    model = sc.ScannerModel(arm=ARM)
    doc = diagnose(model, tab, adapter=ds.adapter(model, tab), settings=NO_BOOT)
    assert doc["unexplained"] is False and doc["findings"] == []


def test_the_former_smooth_test_misses_these_bumps(monkeypatch):
    """Guard of the test's premise: with the smooth basis's grouped F (scan off, sign-flip reference
    and the estimated-Ψ whitener, as before the physical repeatability model and the findings' check) the same bumps are not
    located, so the test above measures the change."""
    orig = lack_of_fit.test
    monkeypatch.setattr(lack_of_fit, "test", lambda *a, **k: orig(*a, **{**k, "scan": False}))
    orig_ad = ds.adapter
    monkeypatch.setattr(ds, "adapter", lambda m, t: dataclasses.replace(orig_ad(m, t), cluster_model=None))
    for amp, seed in CASES:
        # and without the findings' sign-flip check, which drops 10008's J2 scale (a proxy of the
        # bump) and so lets even the smooth test locate it
        doc, centre = bump_run(amp, seed, Settings(n_boot=0, sign_flips=0))
        assert not located(doc, centre)


@pytest.mark.parametrize("divisors", [(12,), (3,)])
def test_scan_finds_a_single_bump_at_its_centre(divisors):
    """The scan's best element on a noise-free single bump (through a unit gain) is centred on it."""
    v = np.linspace(-1.0, 1.0, 200)
    var = lack_of_fit.smooth_variable("x", "rad", v, np.ones((v.size, 1)))
    w = 2.0 / divisors[0]
    r = np.exp(-0.5 * ((v - 0.25) / w) ** 2)
    QA = lack_of_fit.orthonormal(np.ones((v.size, 1)))
    scan = lack_of_fit.scan_basis(var, QA, divisors=divisors)
    rp = lack_of_fit.project_out(r[:, None], QA)
    b = lack_of_fit.best_element(scan, rp[:, 0])
    assert abs(scan.centres[b] - 0.25) <= 2.0 / (lack_of_fit.N_SCAN - 1) / 2 + 1e-9
    # the scan statistic's best element is the same one (one column per element: F grows with the gain)
    assert lack_of_fit.scan_statistic(scan, rp, np.sum(rp**2, axis=0), v.size - 1)[1][0] == b


# ----- the parametric reference (physical repeatability model) ---------------------------------
OLD_MISSES = [(2e-3, 10_036), (2e-3, 10_038)]  # the sign-flip reference's p: 0.11 and 0.024 (bump on 4-6 poses)


def test_parametric_reference_locates_bumps_the_sign_flips_cannot(monkeypatch):
    """A bump acting on 4-6 poses: the sign flips cannot give p below ≈ 2^−(k−1) (Holm needs 0.01/7);
    the reference drawn from the fitted repeatability model (`scanner.repeatability_model`) can."""
    for amp, seed in OLD_MISSES:
        doc, centre = bump_run(amp, seed, NO_BOOT)
        assert located(doc, centre), (amp, seed)
    orig = ds.adapter
    monkeypatch.setattr(ds, "adapter", lambda m, t: dataclasses.replace(orig(m, t), cluster_model=None))
    for amp, seed in OLD_MISSES:  # premise: the sign-flip reference misses them
        doc, centre = bump_run(amp, seed, NO_BOOT)
        assert not located(doc, centre), (amp, seed)


def test_repeatability_basis_is_the_simulators_pose_error_to_first_order():
    """`repeatability_basis` (n, 3, 6) against the simulator: the flange moved by (δt, δω) after the
    stripe was put on the grid line; residuals at the true geometry, no other noise."""
    from pipeline.models.transforms import rot
    c = ss.Campaign(poses=4, corners=5, seed=10_000, capture_speed_rad_s=0.1)
    sim, tab = ss.simulate_in_memory(ARM, ARM, truth(), c, noise=ss.Noise(scale=0))
    model = sc.ScannerModel(arm=ARM)
    s = truth()
    x = np.concatenate([s, np.zeros(len(model.parameter_names()) - s.size)])
    B = ds.repeatability_basis(model, x, tab)
    rng = np.random.default_rng(1)
    for g in range(4):
        i = np.flatnonzero(tab["pose"] == g)
        e = rng.normal(0, 1e-5, 6)
        R_c, C = ss._camera_pose(ARM.vector(), s, tab["joint_positions"][i[:1]],
                                 (rot("x", e[3]) @ rot("y", e[4]) @ rot("z", e[5]), e[:3]))
        p0, dvec = ss._floor_line(R_c, C, s, 0.0)
        X = tab["corner"][i]
        Y = p0 + ((X - p0) @ dvec[0])[:, None] * dvec
        px, _ = ss._project(np.repeat(R_c, i.size, 0), np.repeat(C, i.size, 0), s, Y)
        r = model.residuals(x, {**{k: v[i] for k, v in tab.items()}, "pixel": px}).ravel()
        assert np.linalg.norm(r - B[i].reshape(-1, 6) @ e) < 1e-3 * np.linalg.norm(r)


def test_joint_level_mechanisms_are_the_simulators_to_first_order():
    """`repeatability_model`'s joint-level columns against the simulator: the arm standing δq off at the
    capture (slide, last n_joints columns) and the encoders reading δq off (pure rigid, `encoder_basis`);
    residuals at the true geometry, no other noise."""
    c = ss.Campaign(poses=4, corners=5, seed=10_000, capture_speed_rad_s=0.1)
    sim, tab = ss.simulate_in_memory(ARM, ARM, truth(), c, noise=ss.Noise(scale=0))
    model = sc.ScannerModel(arm=ARM)
    s = truth()
    x = np.concatenate([s, np.zeros(len(model.parameter_names()) - s.size)])
    B, groups = ds.repeatability_model(model, x, tab)
    Bq, Bs = B[:, :, groups[4]], B[:, :, groups[5]]
    rng = np.random.default_rng(2)
    for g in range(4):
        i = np.flatnonzero(tab["pose"] == g)
        dq = rng.normal(0, 1e-5, Bq.shape[2])
        q = tab["joint_positions"][i[:1]]
        R_c, C = ss._camera_pose(ARM.vector(), s, q + dq, (np.eye(3), np.zeros(3)))
        p0, dvec = ss._floor_line(R_c, C, s, 0.0)
        X = tab["corner"][i]
        Y = p0 + ((X - p0) @ dvec[0])[:, None] * dvec
        px, _ = ss._project(np.repeat(R_c, i.size, 0), np.repeat(C, i.size, 0), s, Y)
        sub = {k: v[i] for k, v in tab.items()}
        r = model.residuals(x, {**sub, "pixel": px}).ravel()  # slide: the arm at q + δq, the encoders read q
        assert np.linalg.norm(r - Bs[i].reshape(-1, Bs.shape[2]) @ dq) < 1e-3 * np.linalg.norm(r)
        r = model.residuals(x, {**sub, "joint_positions": sub["joint_positions"] + dq}).ravel()  # encoders off
        assert np.linalg.norm(r - Bq[i].reshape(-1, Bq.shape[2]) @ dq) < 1e-3 * np.linalg.norm(r)


def test_physical_components_recover_the_variances():
    """REML estimates of the repeatability model's six variances on residuals drawn from it (geometry
    fitted out): the pose covariance they imply is unbiased (mean over 12 draws within 15 %) and each
    draw's within 30 % (median)."""
    from pipeline.diagnose.inference import clustered
    tab = campaign(10_000)
    model = sc.ScannerModel(arm=ARM)
    x = np.concatenate([truth(), np.zeros(len(model.parameter_names()) - truth().size)])
    B, groups = ds.repeatability_model(model, x, tab)
    nk = B.shape[0] * 3
    B = B.reshape(nk, -1)
    cl = np.repeat(tab["pose"], 3)
    A = model.jacobian(x, tab).reshape(nk, -1)
    A = A[:, np.linalg.norm(A, axis=0) > 0]
    src = [np.zeros((nk // 3, 3, 1))]
    true = np.array([2e-9, 5e-8, 1e-9, 2e-8, 1e-8, 4e-8])  # flange slide: δt, δω; rigid: δt, δω; δq rigid, slide
    pm = clustered.PhysicalModel(src, np.array([0.0, 1e-10]), B, groups, true, cl)  # isotropic 1e-5 m noise
    Y = pm.draw(12, 2)
    with one_thread():  # small dense algebra: OpenBLAS's threads only spin-wait on a busy box
        est = np.array([clustered.physical_components(Y[:, j], A, B, groups, cl, 1e-10) for j in range(12)])
    # the mechanisms overlap (a flange rotation and the joints' rotations reach the points alike), so
    # single variances trade off against each other; what the reference uses is the covariance they imply
    def cov(theta):
        cv = clustered.PhysicalModel(src, np.zeros(2), B, groups, theta, cl).column_variances()
        return np.einsum("rp,sp,p->rs", B, B, cv) * (cl[:, None] == cl[None, :])
    Vt = cov(true)
    err = [np.linalg.norm(cov(e) - Vt) / np.linalg.norm(Vt) for e in est]
    bias = np.linalg.norm(np.mean([cov(e) for e in est], axis=0) - Vt) / np.linalg.norm(Vt)
    assert bias < 0.15 and np.median(err) < 0.3, (bias, err)  # measured: 0.095, 0.21


# ----- encoder-type pose errors (the arm where the stripe was placed, the encoders δq off) -------
ENCODER = ss.Noise(repeatability_3sigma_m=0.0, encoder_repeatability_rad=1e-4)
ENCODER_FALSE_ALARMS = [10_002, 10_005, 10_020]  # clean; `unexplained` (q_J3, q_J2, q_J2) before the encoder mechanism


def noisy_run(seed: int, effects=(), noise: ss.Noise = ENCODER) -> tuple[dict, dict]:
    """Diagnosis (no bootstrap) of a benchmark campaign simulated with `noise`, and its table."""
    c = ss.Campaign(poses=20, corners=5, seed=seed, capture_speed_rad_s=0.1)
    sim, tab = ss.simulate_in_memory(ARM, ARM, truth(), c, noise, effects=tuple(parse_effect(e) for e in effects),
                                     plan_cache=PLANS)
    tab = ds.add_context(tab, sim.stream_t_ns, sim.stream_q)
    model = sc.ScannerModel(arm=ARM)
    return diagnose(model, tab, adapter=ds.adapter(model, tab), settings=NO_BOOT), tab


def test_reference_holds_its_size_under_encoder_type_pose_errors():
    """Encoder misreadings move a pose's points rigidly, shaped by the arm's Jacobian (anisotropic,
    pose-dependent): with only isotropic flange mechanisms the reference was too narrow and these
    clean campaigns read `unexplained` (3 of seeds 10000–10079); `scanner.encoder_basis` models them.  And a J2
    bump under the same noise is still located (one variance for all joints does not absorb it)."""
    for seed in ENCODER_FALSE_ALARMS:
        doc, _ = noisy_run(seed)
        assert not doc["unexplained"], (seed, doc["unexplained_where"])
    _, tab = noisy_run(10_000)
    q2 = np.unique(tab["joint_positions"][:, 1])
    centre = float(np.sort(q2)[len(q2) // 2])
    doc, _ = noisy_run(10_000, [f"bump=1e-3@J2:{centre:.4f}"])
    assert located(doc, centre), doc["unexplained_where"]


SCALE_MISSES = [(ss.Noise(), 10_035), (ss.Noise(joint_repeatability_rad=1.5e-4), 10_026),
                (ss.Noise(joint_repeatability_rad=1.5e-4), 10_055)]  # clean; `unexplained` with θ̂ plugged in


def test_reference_carries_the_variances_estimation_error():
    """The REML variances of 20 poses are ~20–30 % uncertain; plugged in as known, the reference read these
    clean campaigns (default flange error; joint-level + flange) as `unexplained`.  Each draw scales them
    by χ²_ν/ν (`PhysicalModel.scale_dof`), and they are clean."""
    for noise, seed in SCALE_MISSES:
        doc, _ = noisy_run(seed, noise=noise)
        assert not doc["unexplained"], (seed, doc["unexplained_where"])
