"""report.html: content checked against the run's figures, self-contained, and rendered by headless
Chromium (DOM has every figure, the screenshot is not blank); the diagnosis section from a
diagnosis.json of the residual diagnosis' shape."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from pipeline.report.artefacts import load_run
from pipeline.report.html import diagnosis_section
from report_support import copy_run, report_run  # noqa: F401  (session fixture)

FIGURES = ("fig-residuals-group", "fig-residuals-time", "fig-residuals-joints", "fig-singular", "fig-correlation",
           "fig-solver")
SECTIONS = ("summary", "residuals", "parameters", "observability", "solver", "validation", "provenance")


def chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


def _chromium(args: list[str], tmp: Path) -> subprocess.CompletedProcess:
    exe = chromium()
    if exe is None:
        pytest.skip("chromium not found (install it with `make chromium`, or apt-get install chromium)")
    base = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
            "--disable-background-networking", "--disable-component-update", "--disable-sync",
            f"--user-data-dir={tmp / 'profile'}"]
    return subprocess.run(base + args, capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def html(report_run) -> str:  # noqa: F811
    return (report_run / "report.html").read_text(encoding="utf-8")


def test_summary_figures_match_the_identify_stage(html, report_run):  # noqa: F811
    fit = json.loads((report_run / "identify" / "fit.json").read_text())
    for key in ("rms_before_m", "rms_after_m", "holdout_rms_m"):
        assert f"{fit[key] * 1e3:.4f} mm" in html, key
    assert f"{int(np.sum(fit['free']))} / {len(fit['names'])}" in html
    # the parameter table: one row per parameter, base.x shown in mm (nominal 340 mm)
    rows = re.findall(r"<tr(?: class=\"fixed\")?><td><code>([^<]+)</code></td><td>(mm|deg)</td>", html)
    assert [r[0] for r in rows] == fit["names"]
    i = fit["names"].index("base.x")
    assert f"<code>base.x</code></td><td>mm</td><td class=\"n\">{fit['nominal'][i] * 1e3:.4f}</td>" in html
    i = fit["names"].index("base.rz")
    assert f"<code>base.rz</code></td><td>deg</td><td class=\"n\">{np.degrees(fit['nominal'][i]):.4f}</td>" in html


def test_sections_figures_and_provenance(html, report_run):  # noqa: F811
    for s in SECTIONS:
        assert f'<section id="{s}">' in html, s
    for f in FIGURES:
        assert re.search(rf'<figure id="{f}" class="plot"><svg', html), f
    rec = json.loads((report_run / "ingest" / "recording.json").read_text())
    assert rec["source"]["sha256"] in html
    assert "robocal 0." in html or "robocal version" in html
    for check in json.loads((report_run / "validate" / "validate.json").read_text())["checks"]:
        assert check["name"] in html
    # self-contained: no script, no external resource
    assert "<script" not in html
    assert not re.search(r'(src|href)="(https?:)?//', html)
    assert 'xlink:href="http' not in html


def test_report_stage_is_deterministic_and_cached(report_run, tmp_path):  # noqa: F811
    from pipeline.stages.runner import run_stage

    from pipeline import __version__
    from pipeline.report.html import render

    d = copy_run(report_run, tmp_path / "run")
    before = (d / "report.html").read_text(encoding="utf-8")
    out = run_stage(d, "report", {})
    assert out.cached  # nothing changed
    assert render(load_run(d), __version__, {}) == before  # the same artefacts give the same page, byte for byte


def test_chromium_renders_every_figure(report_run, tmp_path):  # noqa: F811
    url = (report_run / "report.html").resolve().as_uri()
    dom = _chromium(["--dump-dom", url], tmp_path)
    assert dom.returncode == 0, dom.stderr[-2000:]
    for f in FIGURES:
        m = re.search(rf'<figure id="{f}" class="plot">(.*?)</figure>', dom.stdout, re.S)
        assert m, f"figure {f} missing from the rendered DOM"
        assert m.group(1).count("<path") + m.group(1).count("<use") > 10, f"figure {f} has no drawing"
    assert "This page isn" not in dom.stdout and "ERR_" not in dom.stdout

    shot = tmp_path / "report.png"
    r = _chromium([f"--screenshot={shot}", "--window-size=1280,4000", url], tmp_path)
    assert r.returncode == 0 and shot.is_file(), r.stderr[-2000:]
    from matplotlib.image import imread

    img = imread(shot)[..., :3]
    assert img.shape[:2] == (4000, 1280)
    assert img.std() > 0.05  # not blank
    dark = (img.mean(axis=2) < 0.5).mean()
    assert 0.005 < dark < 0.5  # text and plots drawn on a light page
    colourful = (img.max(axis=2) - img.min(axis=2) > 0.3).mean()
    assert colourful > 0.001  # the coloured plot markers rendered


DIAGNOSIS = {
    "findings": [{
        "effect": "joint_compliance", "location": {"joint": "J2"},
        "parameters": [{"name": "k_J2", "value": 2.1e-6, "std": 1.0e-7, "unit": "rad/Nm"}],
        "evidence": {"F": 41.2, "p_value": 1e-6, "delta_bic": -35.0, "cv_rms_before_m": 2.0e-4,
                     "cv_rms_after_m": 5.1e-5, "bootstrap_frequency": 0.99},
        "absorbed_fraction": 0.31}],
    "not_identifiable": [{"effect": "touch_latency", "absorbed_by": "tool.z",
                          "advice": "vary the search speed"}],
    "unexplained": False,
    "holdout_rms_before_m": 2.0e-4, "holdout_rms_after_m": 5.1e-5,
}


def test_diagnosis_section(report_run, tmp_path):  # noqa: F811
    d = copy_run(report_run, tmp_path / "run")
    (d / "diagnose").mkdir(exist_ok=True)
    doc = dict(DIAGNOSIS)
    n = 40
    doc["plots"] = [{"title": "added-variable plot: J2 torque", "x_label": "J2 gravity torque (N·m)",
                     "x": list(np.linspace(-50, 50, n)), "before_m": list(np.linspace(-2e-4, 2e-4, n)),
                     "after_m": list(np.zeros(n))}]
    (d / "diagnose" / "diagnosis.json").write_text(json.dumps(doc))
    html = diagnosis_section(load_run(d))
    assert '<section id="diagnosis">' in html
    assert "joint_compliance" in html and "joint: J2" in html and "vary the search speed" in html
    assert "0.2000 mm" in html and "0.0510 mm" in html  # held-out RMS before/after
    assert re.search(r'<figure id="fig-diagnosis-improvement" class="plot"><svg', html)
    assert re.search(r'<figure id="fig-diagnosis-0" class="plot"><svg', html)
    assert "added-variable plot: J2 torque" in html
    assert "sign-flip check" not in html

    # a look-alike the campaign cannot reject is named beside the finding
    doc["findings"] = [dict(doc["findings"][0], look_alikes=[{"effect": "joint_compliance", "location": "J3",
                                                             "delta_chi2": 1.5}])]
    (d / "diagnose" / "diagnosis.json").write_text(json.dumps(doc))
    assert "can hardly tell it from joint_compliance@J3" in diagnosis_section(load_run(d))

    # a finding the pose sign-flip check dropped (scanner) is named as such
    doc["clustered_inference"] = {"dropped_by_check": [{"effect": "joint_scale", "location": "J3"}]}
    (d / "diagnose" / "diagnosis.json").write_text(json.dumps(doc))
    html = diagnosis_section(load_run(d))
    assert "not confirmed by the pose sign-flip check" in html and "joint_scale@J3" in html

    # without plot data, the report draws the residuals against the located variable itself
    (d / "diagnose" / "diagnosis.json").write_text(json.dumps(DIAGNOSIS))
    html = diagnosis_section(load_run(d))
    assert re.search(r'<figure id="fig-diagnosis-0" class="plot"><svg', html)
    assert "against J2 (deg)" in html


def test_diagnosis_section_follows_the_diagnose_stage(html, report_run, tmp_path):  # noqa: F811
    if (report_run / "diagnose" / "diagnosis.json").is_file():  # the real stage ran: its section is there
        doc = json.loads((report_run / "diagnose" / "diagnosis.json").read_text())
        assert '<section id="diagnosis">' in html and 'href="#diagnosis"' in html
        for t in doc.get("lack_of_fit", []):
            assert t["variable"] in html
    d = copy_run(report_run, tmp_path / "run")
    shutil.rmtree(d / "diagnose", ignore_errors=True)
    assert diagnosis_section(load_run(d)) == ""
