"""The diagnosis' verdict functions: floor check, outliers, influence, arbiter, status."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.diagnose.inference import resampling
from pipeline.diagnose.verdict import arbiter, checks
from pipeline.identify.least_squares import kfold_indices


def _design(n: int, p: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(n, p))


def test_floor_check_holds_its_size_on_noise_at_the_floor_and_rejects_above_it():
    rng = np.random.default_rng(0)
    var = np.full(100, (3e-5) ** 2)
    p = [checks.floor_check(rng.normal(0, 3e-5, 100), 100, var, 0.01)["p_value"] for _ in range(400)]
    assert 0.0 <= np.mean(np.array(p) < 0.01) <= 0.03  # size ≈ α
    above = checks.floor_check(rng.normal(0, 4.5e-5, 100), 100, var, 0.01)  # 1.5× the floor
    assert above["above_floor"] and above["rms_over_floor"] > 1.3


def test_touch_floor_variance_adds_repeatability_encoder_and_jig():
    Jq = np.zeros((2, 6))
    Jq[1, 1] = 1.0  # 1 m lever on J2
    v = checks.touch_floor_variance(Jq, 1e-4, 2e-5, count_rad=1e-5)
    assert np.isclose(v[0], (1e-4 / 3) ** 2 + (2e-5) ** 2 / 3)
    assert np.isclose(v[1] - v[0], 1e-10 / 12)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), row=st.integers(0, 79), size=st.floats(12.0, 40.0))
def test_one_gross_error_is_named_alone(seed, row, size):
    """A gross error on one record is flagged first, and it does not drag clean records over the bound."""
    J = _design(80, 10, seed)
    rng = np.random.default_rng(seed + 1)
    r = rng.normal(0, 1.0, 80)
    r[row] += size * np.sign(rng.normal() or 1.0)
    out = checks.studentized_outliers(J, r, 0.01)
    assert out and out[0][0] == row
    assert len(out) <= 2  # at most one clean record beyond a Bonferroni bound at α = 0.01 (rare)


def test_clean_records_are_rarely_flagged():
    flagged = sum(bool(checks.studentized_outliers(_design(100, 20, s), np.random.default_rng(s).normal(size=100),
                                                    0.01)) for s in range(200))
    assert flagged <= 6  # family α = 0.01 per campaign: ~2 of 200 expected


def test_a_finding_carried_by_one_record_is_that_records():
    rng = np.random.default_rng(3)
    D = _design(100, 8, 3)
    y = rng.normal(0, 1.0, 100)
    S = np.zeros((100, 1))
    S[17, 0] = 1.0  # a column that only reaches record 17 (e.g. a signature concentrated on one contact)
    S[:, 0] += 0.05 * rng.normal(size=100)
    y[17] += 8.0
    assert checks.carried_by(y, D, S, 0.01) == [17]
    # a real effect spread over every record is not carried by any one or two
    S2 = rng.normal(size=(100, 1))
    assert checks.carried_by(rng.normal(0, 1.0, 100) + 0.8 * S2[:, 0], D, S2, 0.01) is None


def test_misspecified_flags_a_form_that_misses_structure_along_its_variable():
    from pipeline.diagnose.verdict.lack_of_fit import smooth_variable

    rng = np.random.default_rng(5)
    t = np.linspace(0, 1000, 120)
    A = np.column_stack([np.ones(120), t])  # a linear drift fitted ...
    y = 5.0 * (1 - np.exp(-t / 200)) + rng.normal(0, 0.3, 120)  # ... to an exponential warm-up
    r = y - A @ np.linalg.lstsq(A, y, rcond=None)[0]
    v = smooth_variable("time_since_start_s", "s", t, np.ones((120, 1)), K=6)
    assert checks.misspecified(r, A, [v], 0.01) is not None
    y2 = 0.004 * t + rng.normal(0, 0.3, 120)  # a true linear drift leaves nothing along time
    r2 = y2 - A @ np.linalg.lstsq(A, y2, rcond=None)[0]
    assert checks.misspecified(r2, A, [v], 0.01) is None


def test_arbiter_reports_nothing_when_the_model_is_worse_out_of_sample():
    """A finding fitted to noise (here: 30 free columns on 60 rows) makes the held-out RMS worse: it
    is rejected and the final model is the geometry."""
    rng = np.random.default_rng(7)
    n = 60
    Jf = _design(n, 4, 7)
    r = rng.normal(0, 1.0, n)
    r -= Jf @ np.linalg.lstsq(Jf, r, rcond=None)[0]
    S = rng.normal(size=(n, 30))
    A = np.hstack([Jf, S])
    coef = np.linalg.lstsq(A, r, rcond=None)[0]
    r_final = r - A @ coef
    contrib = -(S @ coef[4:])[:, None]
    folds = kfold_indices(n, 5, 0, np.arange(n) // 5)
    before, after = resampling.holdout(Jf, r, folds), resampling.holdout(A, r_final, folds)
    assert resampling.rms(after) > resampling.rms(before)
    fd = {"effect": "noise", "location": "x", "confidence": "high",
          "evidence": {"cv_rms_before_m": 0.0, "cv_rms_after_m": -1.0}}  # its own ablation looks fine ...
    fin = arbiter.Final([fd], [0], [contrib], {0: list(range(4, 34))}, A, r_final, after)
    out, rejected, worse, all_cv = arbiter.arbiter(fin, folds, Jf, r, before)
    assert worse and not out.findings and rejected[0]["confidence"] == "rejected"  # ... the whole model is not
    assert resampling.rms(out.after_cv) == resampling.rms(before) and all_cv > resampling.rms(before)


def test_status_names_what_is_left():
    fl = {"above_floor": True}
    assert checks.status(1, False, fl, False)[0] == "partially_explained"
    assert checks.status(1, False, {"above_floor": False}, False)[0] == "explained"
    assert checks.status(1, False, None, False, ["time_since_start_s→growth"])[0] == "partially_explained"
    assert checks.status(0, True, None, False)[0] == "unexplained"
    assert checks.status(0, False, fl, False)[0] == "unexplained"
    assert checks.status(0, False, None, False)[0] == "clean"
    assert checks.status(2, False, None, True)[0] == "model_worse_out_of_sample"


def test_advice_names_what_to_do_where_structure_is_left():
    assert "top2" in checks.advice_for("face top2 position")
    assert "J2 alone" in checks.advice_for("q_J2→J3")
    assert "temperature" in checks.advice_for("time_since_start_s→growth")
    assert "J5" in checks.advice_for("q_J5")


def test_holdout_floor_check_is_calibrated_on_noise_at_the_floor():
    """The held-out residuals' null (a quadratic form in the floor errors) gives about uniform p-values."""
    rng = np.random.default_rng(11)
    n = 60
    A = _design(n, 6, 11)
    folds = kfold_indices(n, 5, 0, np.arange(n) // 5)
    v = rng.uniform(0.5, 2.0, n)  # heteroscedastic floor
    p = []
    for _ in range(300):
        e = rng.normal(0, np.sqrt(v))
        r = e - A @ np.linalg.lstsq(A, e, rcond=None)[0]
        p.append(checks.holdout_floor_check(A, resampling.holdout(A, r, folds), folds, v, 0.01)["holdout_p_value"])
    p = np.array(p)
    assert 0.02 <= np.mean(p < 0.05) <= 0.09 and 0.4 <= np.mean(p < 0.5) <= 0.6
    e = rng.normal(0, 1.4 * np.sqrt(v))  # 1.4× the floor
    r = e - A @ np.linalg.lstsq(A, e, rcond=None)[0]
    assert checks.holdout_floor_check(A, resampling.holdout(A, r, folds), folds, v, 0.01)["holdout_p_value"] < 0.05


@settings(max_examples=40, deadline=None)
@given(size=st.floats(0.0, 0.05), sd=st.floats(1e-5, 0.01), phase=st.floats(0.0, 2 * np.pi))
def test_a_finding_fitted_beyond_its_plausible_size_is_a_proxy_not_the_physics(size, sd, phase):
    """A named term fitted more than 2σ beyond the size its library entry holds physically plausible (an elastic
    lag of 24 mrad/(N·m) where 10 is the most a joint gives) is reported as a likely proxy and graded `low`;
    within 2σ of it the name stands.  A two-phase term's size is its amplitude, whatever the phase."""
    from pipeline.diagnose.library.term import Effect
    from pipeline.diagnose.verdict.grading import beyond_plausible

    def effect(params, units):
        return Effect(name="joint_elasticity", location="arm_4", parameters=params, units=units, plausible=0.01,
                      where="joint", basis=lambda *a: None, priority=0, variable="torque", advice="")

    one = effect(("c",), ("rad/(N·m)",))
    fd = {"parameters": [{"name": "c", "value": -size, "std": sd, "unit": "rad/(N·m)"}]}
    note = beyond_plausible(fd, one)
    assert (note is not None) == (size - 2 * sd > 0.01)
    if note:
        assert "beyond the 0.01 rad/(N·m)" in note and "proxy" in note
    two = effect(("a_cos", "a_sin", "v"), ("rad", "rad", "rad/s"))  # a third parameter in another unit: not the size
    fd2 = {"parameters": [{"name": "a_cos", "value": size * np.cos(phase), "std": sd, "unit": "rad"},
                          {"name": "a_sin", "value": size * np.sin(phase), "std": sd / 2, "unit": "rad"},
                          {"name": "v", "value": 100.0, "std": 0.0, "unit": "rad/s"}]}
    if abs(size - 2 * sd - 0.01) > 1e-12:  # the amplitude is the size up to round-off
        assert (beyond_plausible(fd2, two) is not None) == (size - 2 * sd > 0.01)
