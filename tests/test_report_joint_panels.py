"""The report's per-joint residual figures stay readable for a robot of many joints: the accuracy
section's "residuals against each joint angle" (before / after) wraps at three joints a row as the
residuals section does, and in a real browser (headless Chromium) no two of its text labels overlap
— 18 joints in one row did (a humanoid's names drawn over each other)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from test_report_html import _chromium

# an 18-joint humanoid's names, long as real URDFs spell them
NAMES = [f"{side}_{part}_joint_{k}" for side in ("left", "right") for part in ("arm", "leg") for k in range(1, 5)]
NAMES += ["torso_yaw_joint", "head_pitch_joint"]

OVERLAPS = """
<script>
const texts = [...document.querySelectorAll('svg text')].filter(t => t.textContent.trim());
const boxes = texts.map(t => t.getBoundingClientRect());
const svg = document.querySelector('svg').getBoundingClientRect();
let overlaps = [];
for (let i = 0; i < boxes.length; i++) for (let j = i + 1; j < boxes.length; j++) {
  const a = boxes[i], b = boxes[j];
  const w = Math.min(a.right, b.right) - Math.max(a.left, b.left), h = Math.min(a.bottom, b.bottom) - Math.max(a.top, b.top);
  if (w > 1 && h > 1) overlaps.push([texts[i].textContent, texts[j].textContent]);
}
document.getElementById('out').textContent = JSON.stringify({n: texts.length, overlaps: overlaps,
  width: svg.width, outside: boxes.filter(b => b.right > svg.right + 1 || b.left < svg.left - 1).length});
</script>"""


def _render(svg: str, tmp_path) -> dict:
    page = tmp_path / "joints.html"
    page.write_text(f'<!DOCTYPE html><html><body style="margin:0">{svg}<pre id="out"></pre>{OVERLAPS}</body></html>')
    r = _chromium(["--window-size=1280,3000", "--dump-dom", page.resolve().as_uri()], tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(re.search(r'<pre id="out">(.*?)</pre>', r.stdout, re.S).group(1))


@pytest.mark.parametrize("n", [18, 3])
def test_per_joint_figure_wraps_and_no_label_overlaps_in_a_browser(tmp_path, n):
    from pipeline.report.accuracy import JOINT_COLUMNS, joints_before_after

    rng = np.random.default_rng(0)
    names = NAMES[:n]
    joints = {j: rng.uniform(-2.0, 2.0, 40) for j in names}
    before, after = rng.normal(0, 3e-3, (40, 3)), rng.normal(0, 2e-4, (40, 3))
    svg = joints_before_after(joints, before, after)
    assert all(f"{j} (deg)" in svg for j in names)
    # columns of panels: the distinct x positions of the x-axis labels (one per joint, drawn under its "after" panel)
    xs = {round(float(x)) for x in re.findall(r'<text[^>]*x="([\d.]+)"[^>]*>[^<]*_joint[^<]* \(deg\)</text>', svg)}
    assert len(xs) == min(n, JOINT_COLUMNS), sorted(xs)
    res = _render(svg, tmp_path)
    assert res["n"] > 2 * n and not res["overlaps"], res["overlaps"][:5]
    assert res["outside"] == 0
    assert res["width"] <= 1000  # 9.5 in at most: fits the report's column, whatever the joint count
