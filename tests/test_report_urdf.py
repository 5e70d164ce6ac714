"""The report of a URDF robot speaks of that robot: its name in the title, its joints by their URDF
names, a prismatic joint in mm (not degrees), the table row (not seconds) for a campaign without
times, no jig faces; log axes labelled in plain text; no empty p-value column."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from conftest import run_cli


@pytest.fixture(scope="module")
def urdf_run(tmp_path_factory) -> Path:
    from test_urdf_simulate import PR6

    d = tmp_path_factory.mktemp("urdf_report")
    (d / "r.urdf").write_text(PR6)
    rec = d / "sim.mcap"
    p = run_cli("simulate", "urdf", "--urdf", d / "r.urdf", "--root", "base", "--tip", "flange", "--measure", "point",
                "--poses", "30", "--noise-mm", "0.05", "--out", rec)
    assert p.returncode == 0, p.stderr
    p = run_cli("run", rec, "--out", d / "run")
    assert p.returncode == 0, p.stderr
    return d / "run"


def _labels(html: str) -> list[str]:
    """Every text element of the report's inline SVG figures."""
    return [re.sub(r"\s+", " ", t).strip() for t in re.findall(r"<text[^>]*>([^<]*)</text>", html)] + \
        re.findall(r"<!-- (.*?) -->", html)


def test_report_names_the_robot_its_joints_and_units(urdf_run):
    from pipeline.models.urdf import parse
    from test_urdf_simulate import PR6

    html = (urdf_run / "report.html").read_text()
    desc = parse(PR6, "base", "flange")
    assert re.search(r"<title>robocal report — torso_arm \(urdf\)</title>", html)
    prismatic = [j.name for j in desc.movable if j.type == "prismatic"]
    revolute = [j.name for j in desc.movable if j.type != "prismatic"]
    assert prismatic and revolute
    text = html + "\n".join(_labels(html))
    for j in prismatic:
        assert f"{j} (mm)" in text and f"{j} (deg)" not in text
    for j in revolute:
        assert f"{j} (deg)" in text
    assert not re.search(r"\bJ[1-9] \(deg\)", text), "joints shown as J1… instead of their names"
    assert "mathdefault" not in html and "$" not in "".join(_labels(html))
    assert "face" not in re.sub(r"<svg.*?</svg>", "", html, flags=re.S).lower().replace("interface", "")
    assert "measurement (table row)" in text and "time since first measurement" not in text


def test_lack_of_fit_table_has_no_empty_column(urdf_run):
    html = (urdf_run / "report.html").read_text()
    m = re.search(r"<h3>Lack-of-fit tests</h3>(<table.*?</table>)", html, re.S)
    if m is None:
        pytest.skip("no lack-of-fit table in this run")
    head = re.findall(r"<th[^>]*>(.*?)</th>", m.group(1))
    rows = re.findall(r"<tr>(.*?)</tr>", m.group(1), re.S)[1:]
    cells = [re.findall(r"<td[^>]*>(.*?)</td>", r) for r in rows]
    for k, h in enumerate(head):
        assert any(c[k] not in ("", "–") for c in cells if len(c) > k), f"column {h!r} is empty"


def test_log_axis_ticks_are_plain_text():
    from pipeline.report import plots

    svg = plots.singular_values(np.array([30.0, 4.0, 0.5, 0.02]))
    ticks = [t for t in _labels(svg) if t]
    assert "mathdefault" not in svg and not any("$" in t for t in ticks)
    assert {"0.1", "1", "10"} <= set(ticks), ticks


def test_chromium_renders_the_urdf_report(urdf_run, tmp_path):
    """Headless Chromium: the title, the joints by name and a prismatic joint in mm in the rendered DOM,
    and a page with drawn plots."""
    from test_report_html import _chromium

    url = (urdf_run / "report.html").resolve().as_uri()
    dom = _chromium(["--dump-dom", url], tmp_path)
    assert dom.returncode == 0, dom.stderr[-2000:]
    assert "robocal calibration report — torso_arm (urdf)" in dom.stdout
    assert "torso_lift (mm)" in dom.stdout and "mathdefault" not in dom.stdout
    shot = tmp_path / "report.png"
    r = _chromium([f"--screenshot={shot}", "--window-size=1280,3000", url], tmp_path)
    assert r.returncode == 0 and shot.is_file(), r.stderr[-2000:]
    from matplotlib.image import imread

    img = imread(shot)[..., :3]
    assert img.std() > 0.05 and (img.max(axis=2) - img.min(axis=2) > 0.3).mean() > 0.001
