"""Honest accuracy: priors of fixed parameters propagated, the workspace map, the
`insufficient` verdict, --strict, --tolerance, --previous."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import run_cli
from pipeline.accuracy import assess, prior, propagate as P, workspace
from pipeline.errors import RobocalError
from pipeline.identify.least_squares import covariance, fit
from pipeline.identify.model import take
from pipeline.models.jig import stepped_block
from pipeline.plan.arc_welder import measured
from pipeline.systems import arc_welder as aw
from tests.pipeline_support import BUNDLED, base_campaign, write

# extended (`make test-extended`, outside CI's 20-minute budget): stated accuracy against held-out on several campaigns; CI keeps test_accuracy_holdout, test_accuracy_real_sessions
pytestmark = pytest.mark.extended

FIXTURE = stepped_block().to_dict()


# ----- functional core ------------------------------------------------------------------
def test_consider_covariance_matches_monte_carlo_of_a_linear_model():
    """Fixed parameters drawn from their prior and noise drawn at σ: the empirical covariance of
    the calibrated point error equals the predicted fit + prior covariance."""
    rng = np.random.default_rng(0)
    m, p, n = 60, 8, 5
    Jm, Jp = rng.normal(size=(m, p)), rng.normal(size=(n, 3, p))
    free = np.array([1, 1, 1, 1, 1, 0, 0, 0], bool)
    sig_prior, sigma = np.array([0, 0, 0, 0, 0, 0.3, 0.1, 0.2]), 0.05
    A = P.absorption(Jm, free)
    pred = P.predict(Jp, free, covariance(Jm[:, free], sigma), sig_prior, A)
    K = 40_000
    delta = rng.normal(size=(K, p)) * sig_prior  # true − nominal; fixed ones kept at nominal
    y = delta @ Jm.T + rng.normal(0, sigma, (K, m))  # measurement deviations
    est = np.zeros((K, p))
    est[:, free] = y @ np.linalg.pinv(Jm[:, free]).T
    err = np.einsum("nip,kp->kni", Jp, est - delta)
    emp = np.einsum("kni,knj->nij", err, err) / K
    assert np.allclose(emp, pred.cov, rtol=0.05, atol=0.02 * np.abs(pred.cov).max())


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000))
def test_a_fixed_parameter_the_fit_absorbs_contributes_nothing(seed):
    """A fixed column equal to a combination of free ones (in measurements and points alike,
    like J1.θ ≡ base.rz) adds no predicted error; an unmeasured one adds its full effect."""
    rng = np.random.default_rng(seed)
    Jm, Jp = rng.normal(size=(30, 5)), rng.normal(size=(4, 3, 5))
    c = rng.normal(size=4)
    Jm = np.column_stack([Jm[:, :4], Jm[:, :4] @ c])
    Jp = np.concatenate([Jp[:, :, :4], (Jp[:, :, :4] @ c)[:, :, None]], axis=2)
    free = np.array([1, 1, 1, 1, 0], bool)
    A = P.absorption(Jm, free)
    assert np.allclose(P.fixed_contributions(Jp, free, np.full(5, 1.0), A), 0, atol=1e-9)
    Jm[:, 4] = 0  # never measured: its whole effect on the point remains
    A = P.absorption(Jm, free)
    eff = np.sqrt(np.mean(np.sum(Jp[:, :, 4] ** 2, axis=1)))
    assert np.isclose(P.fixed_contributions(Jp, free, np.full(5, 2.0), A)[0], 2 * eff)


def test_95_percent_bound_of_the_error_norm():
    rng = np.random.default_rng(1)
    for lam in ([1.0, 1.0, 1.0], [4.0, 1.0, 0.01], [1.0, 0.0, 0.0]):
        cov = np.diag(lam)[None]
        b = P.norm_quantile(cov, 0.95)[0]
        e = rng.normal(size=(200_000, 3)) * np.sqrt(lam)
        assert abs(np.mean(np.linalg.norm(e, axis=1) <= b) - 0.95) < 0.01, lam


def test_prior_defaults_by_kind_and_overrides():
    model = aw.TouchModel(aw.nominal_arm())
    s, kinds, src = prior.prior_sigma(model)
    names = model.parameter_names()
    k = dict(zip(names, kinds))
    assert k["base.x"] == "frame_translation" and k["J2.a"] == "length" and k["J3.theta_offset"] == "angle"
    assert k["base.rz"] == "frame_rotation"
    s, _, src = prior.prior_sigma(model, {"J*.beta": 0.001}, prior.parse_overrides(["base.x=0.5mm", "angle=0.2deg"]))
    d = dict(zip(names, s))
    assert d["base.x"] == pytest.approx(5e-4) and d["J2.beta"] == pytest.approx(0.2 * np.pi / 180)  # CLI wins
    assert d["J2.a"] == prior.DEFAULTS["length"]
    with pytest.raises(RobocalError, match="matches no parameter"):
        prior.prior_sigma(model, None, {"nosuch": 1.0})
    with pytest.raises(RobocalError, match="cannot read"):
        prior.parse_overrides(["base.x=5 furlongs"])
    assert prior.parse_quantity("0.1mm") == pytest.approx(1e-4)


# ----- the verdict on simulated campaigns (truth known) -------------------------------------
def _verdict(table, model):
    f = fit(model, table)
    s, _, _ = prior.prior_sigma(model)
    mt, _ = workspace.map_table(model, f.x, table, fixture=FIXTURE)
    doc = assess.evaluate(model, f.x, f.free, f.cov, table, s, mt, model.nominal(),
                          direction_advice=assess.touch_advice(FIXTURE))
    truth = aw.random_truth(aw.nominal_arm(), np.random.default_rng(3 + 1_000_003)).vector()
    true = np.linalg.norm(model.points(f.x, mt)[0] - model.points(truth, mt)[0], axis=1)
    return doc, true


@pytest.fixture(scope="module")
def campaign():
    return measured(100, 3, random_errors=True)


def test_normal_campaign_passes_and_prediction_matches_truth(campaign):
    doc, true = _verdict(campaign[1], campaign[0])
    assert doc["status"] == "pass" and doc["reason"] == ""
    ratio = np.sqrt(np.mean(true**2)) / doc["map_rms_1sigma_m"]
    assert 0.6 < ratio < 1.6, ratio
    assert len(doc["map"]["sigma_m"]) == len(doc["map"]["bound95_m"]) == len(doc["map"]["points_m"]) >= 60
    assert np.all(doc["map"]["bound95_m"] > doc["map"]["sigma_m"])


def test_no_x_facing_face_is_insufficient_and_names_the_faces(campaign):
    model, table = campaign
    doc, true = _verdict(take(table, np.asarray(table["axis"]) != 0), model)
    assert doc["status"] == "insufficient" and "along x" in doc["reason"]
    assert "riser12" in doc["advice"] and "end_low" in doc["advice"]
    assert doc["fixed_parameter_contributions"][0]["name"] == "base.x"
    assert np.sqrt(np.mean(true**2)) < np.sqrt(np.mean(doc["map"]["bound95_m"] ** 2))


def test_eight_contacts_are_insufficient_and_bounded(campaign):
    model, table = campaign
    doc, true = _verdict(take(table, np.arange(8)), model)
    assert doc["status"] == "insufficient"
    assert "8 residuals for 8 identified parameters" in doc["reason"] and "more measurements" in doc["advice"]
    assert np.sqrt(np.mean(true**2)) < np.sqrt(np.mean(doc["map"]["bound95_m"] ** 2))


# ----- command line on real recordings --------------------------------------------------
@pytest.fixture(scope="module")
def thin_recording(tmp_path_factory):
    meta, js, contacts = base_campaign(12)
    return write(tmp_path_factory.mktemp("thin") / "thin.mcap", meta, js, contacts[:8])


def test_strict_exits_non_zero_on_thin_data(thin_recording, tmp_path):
    p = run_cli("calibrate", thin_recording, "--out", tmp_path / "c", "--strict", "--folds", "2")
    assert p.returncode == 1, p.stderr
    assert "Traceback" not in p.stderr and "insufficient:" in p.stderr and "advice:" in p.stderr
    doc = json.loads((tmp_path / "c" / "results.json").read_text())
    assert doc["status"] == "insufficient" and doc["status_advice"]


def test_tolerance_verdict_over_the_map(campaign):
    model, table = campaign
    f = fit(model, table)
    s, _, _ = prior.prior_sigma(model)
    mt, _ = workspace.map_table(model, f.x, table, fixture=FIXTURE)
    ok = assess.evaluate(model, f.x, f.free, f.cov, table, s, mt, model.nominal(), tolerance_m=1e-3)
    assert ok["status"] == "pass" and ok["tolerance"]["points_within"] == ok["tolerance"]["points"]
    tight = assess.evaluate(model, f.x, f.free, f.cov, table, s, mt, model.nominal(), tolerance_m=5e-5)
    assert tight["status"] == "fail" and "exceeds the tolerance" in tight["reason"]
    assert tight["tolerance"]["points_within"] < tight["tolerance"]["points"]


def test_calibrate_tolerance_and_previous_on_the_bundled_recording(thin_run, tmp_path):
    prev, _ = thin_run
    p = run_cli("calibrate", BUNDLED, "--out", tmp_path / "b", "--tolerance", "0.05mm", "--strict",
                "--previous", prev, "--folds", "2")
    assert p.returncode == 1 and "Traceback" not in p.stderr
    doc = json.loads((tmp_path / "b" / "results.json").read_text())
    assert doc["status"] == "fail" and "exceeds the tolerance" in doc["status_reason"]
    assert doc["rms_after_m"] == pytest.approx(3.495e-5, rel=0.02)  # the bundled figures do not change
    assert doc["accuracy"]["tolerance"]["status"] == "fail"
    # the 8-contact calibration's parameters are far from these: they show up as moved
    cmp = doc["accuracy"]["previous"]
    names = {r["name"] for r in doc["parameters"] if r["identifiable"]}
    assert 5 <= cmp["compared"] <= 8 and cmp["moved"] and {m["name"] for m in cmp["moved"]} <= names
    assert all(abs(m["z"]) > 3 for m in cmp["moved"]) and "moved since" in p.stderr


def test_bad_prior_is_one_line(thin_recording, tmp_path):
    p = run_cli("calibrate", thin_recording, "--out", tmp_path / "c", "--prior", "nosuch=1mm")
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert len([ln for ln in p.stderr.splitlines() if ln.strip()]) == 1 and "nosuch" in p.stderr


def test_version():
    p = run_cli("--version")
    assert p.returncode == 0 and p.stdout.startswith("robocal ")


# ----- the pipeline: robocal run --strict, the report and run.rrd ------------------------
@pytest.fixture(scope="module")
def thin_run(thin_recording, tmp_path_factory):
    out = tmp_path_factory.mktemp("thinrun") / "run"
    return out, run_cli("run", thin_recording, "--out", out, "--folds", "2", "--strict")


def test_run_strict_on_thin_data_reports_insufficient_everywhere(thin_recording, thin_run):
    import hashlib
    import re

    from rerun.chunk import RrdReader

    out, p = thin_run
    assert p.returncode == 1, p.stderr[-2000:]
    assert "Traceback" not in p.stderr and "insufficient:" in p.stderr and "advice:" in p.stderr
    # one line each, however long (no hard wrap at 80 columns off a terminal)
    assert any(ln.startswith("insufficient: ") and ln.rstrip().endswith("mm)") and len(ln) > 100
               for ln in p.stderr.splitlines()), p.stderr[-1500:]
    assert f"report: {out / 'report.html'}" in p.stderr and f"rerun: {out / 'run.rrd'}" in p.stderr
    s = json.loads((out / "results.json").read_text())["summary"]
    assert s["status"] == "insufficient" and "identified parameters" in s["status_reason"]
    acc = json.loads((out / "accuracy" / "accuracy.json").read_text())
    assert len(acc["map"]["sigma_m"]) == len(acc["map"]["bound95_m"]) == len(acc["map"]["points_m"]) > 20
    html = (out / "report.html").read_text()
    assert re.search(r'id="accuracy-status">insufficient<', html) and "Advice:" in html
    for fig in ("fig-accuracy-map", "fig-histograms", "fig-joints-before-after"):
        m = re.search(rf'<figure id="{fig}" class="plot">(.*?)</figure>', html, re.S)
        assert m and m.group(1).count("<path") + m.group(1).count("<use") > 10, fig
    sha = hashlib.sha256(thin_recording.read_bytes()).hexdigest()[:16]
    assert RrdReader(out / "run.rrd").recordings()[0].recording_id == f"robocal-arc-welder-{sha}"


def test_rerun_viewer_renders_the_panels(thin_run, tmp_path):
    """The real rerun viewer, headless with Mesa's software Vulkan (Debian
    mesa-vulkan-drivers): its screenshot shows the 3-D scene with the accuracy map (viridis
    spheres), the robot (blue), and drawn time-series panels on the right."""
    from viewer_support import viewer_screenshot

    out, _ = thin_run
    img = viewer_screenshot(out / "run.rrd", tmp_path / "viewer.png")
    h, w = img.shape[:2]
    R, G, B = img[..., 0], img[..., 1], img[..., 2]
    scene = (slice(int(0.05 * h), int(0.75 * h)), slice(int(0.13 * w), int(0.53 * w)))
    yellow = (R > 0.6) & (G > 0.6) & (B < 0.35)  # the largest-σ end of viridis
    teal = (R < 0.3) & (G > 0.35) & (B > 0.4) & (G < 0.75)  # its middle
    blue = (B > 0.6) & (R < 0.35) & (G < 0.35)  # the calibrated arm
    assert yellow[scene].mean() > 2e-5 and (yellow | teal)[scene].mean() > 3e-4, "no accuracy map in the 3-D view"
    assert blue[scene].mean() > 1e-3, "no robot in the 3-D view"
    plots = (slice(int(0.05 * h), int(0.27 * h)), slice(int(0.55 * w), int(0.81 * w)))
    colourful = (img.max(axis=2) - img.min(axis=2)) > 0.3
    assert colourful[plots].mean() > 2e-3, "encoder time series not drawn"
    assert img.std() > 0.05


def test_report_renders_in_headless_chromium(thin_run, tmp_path):
    """The report's Accuracy section in a real browser: the map and histograms drawn, the red
    `insufficient` badge on screen near the top of the page."""
    import re
    import shutil
    import subprocess

    from matplotlib.image import imread

    exe = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if exe is None:
        pytest.skip("chromium not found (make chromium)")
    out, _ = thin_run
    url = (out / "report.html").resolve().as_uri()
    base = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
            "--disable-component-update", "--disable-sync", f"--user-data-dir={tmp_path / 'profile'}"]
    dom = subprocess.run(base + ["--dump-dom", url], capture_output=True, text=True, timeout=120)
    assert dom.returncode == 0
    for fig in ("fig-accuracy-map", "fig-histograms", "fig-joints-before-after"):
        m = re.search(rf'<figure id="{fig}" class="plot">(.*?)</figure>', dom.stdout, re.S)
        assert m and m.group(1).count("<path") + m.group(1).count("<use") > 10, fig
    shot = tmp_path / "top.png"
    r = subprocess.run(base + [f"--screenshot={shot}", "--window-size=1280,900", url], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0 and shot.is_file()
    img = imread(shot)[..., :3]
    red = (img[..., 0] > 0.7) & (img[..., 1] < 0.25) & (img[..., 2] < 0.25)  # the badge, #c62828
    assert red.sum() > 50, "the insufficient badge is not on the first screen"


def test_priors_from_the_robot_model_file(tmp_path):
    from pipeline.recording.schemas import META_ROBOT

    meta, js, contacts = base_campaign(12)
    meta[META_ROBOT]["prior_sigma"] = {"base.x": 1e-3, "J*.beta": 2e-3}
    rec = write(tmp_path / "priors.mcap", meta, js, contacts[:8])
    p = run_cli("calibrate", rec, "--out", tmp_path / "c", "--folds", "2", "--prior", "J2.beta=0.1deg")
    assert p.returncode == 0, p.stderr[-1500:]
    pri = {r["name"]: r for r in json.loads((tmp_path / "c" / "results.json").read_text())["accuracy"]["priors"]}
    assert pri["base.x"]["sigma"] == 1e-3 and pri["base.x"]["source"] == "robot model file prior_sigma"
    assert pri["J3.beta"]["sigma"] == 2e-3 and pri["J2.beta"]["source"] == "--prior"
    assert pri["J2.beta"]["sigma"] == pytest.approx(0.1 * np.pi / 180)
    assert pri["J2.a"]["source"] == "default:length"


def test_user_targets_are_reached_and_bad_targets_named(campaign, tmp_path):
    from pipeline.accuracy.stage import read_targets

    model, table = campaign
    f = fit(model, table)
    targets = np.array([[0.10, 0.05, 0.16], [0.20, 0.10, 0.18], [0.25, 0.15, 0.20]])
    csv = tmp_path / "targets.csv"
    csv.write_text("x,y,z\n" + "\n".join(",".join(map(str, t)) for t in targets) + "\n")
    mt, what = workspace.map_table(model, f.x, table, read_targets(csv), FIXTURE)
    pts, _ = model.points(f.x, mt)
    assert "3 user targets" in what and np.allclose(pts, targets, atol=1e-8)
    (tmp_path / "bad.csv").write_text("x,y,z\n0.1,0.2,0.3\n0.1,oops,0.3\n")
    with pytest.raises(RobocalError, match=r"bad.csv: row 3"):
        read_targets(tmp_path / "bad.csv")
