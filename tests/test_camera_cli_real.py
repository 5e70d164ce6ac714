"""The camera guide's commands on the real KUKA eye-in-hand images, run as docs/guide/camera.md prints them
(`robocal import images` with the robot's RobotPosesVec.txt as shipped → `robocal run` → `robocal evaluate`,
then the benchmark's OpenCV comparison on the same split): no traceback, robocal's held-out 2-D reprojection
RMS (through the robot pose alone) beats every OpenCV calibrateHandEye / calibrateRobotWorldHandEye method, and
the hand-eye σ the run states is the image jackknife's, not the independent-corner one.

The guide's blocks are read from the page and run with bash in a folder laid out like the repository's root
(../shared/real-data beside it); skipped, saying so, where the real data are absent.  ≈ 35 s CPU (the run's
stages on 12 images of 1920×1200, the two imports, the evaluation and OpenCV's calibrations).
"""

import json
import os
import re
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
REAL = REPO.parent / "shared" / "real-data"
GUIDE = REPO / "docs" / "guide" / "camera.md"
LINKED = (".venv", "benchmarks", "recordings", "schemas", "docs")


def kuka_blocks() -> list[str]:
    """The guide's ```sh blocks that use the KUKA images or their split, in page order."""
    bodies = re.findall(r"^```sh\n(.*?)^```", GUIDE.read_text(), flags=re.S | re.M)
    return [b for b in bodies if "handeye_rwhe_kuka2" in b or "kuka-train" in b]


@pytest.fixture(scope="module")
def guide_run(tmp_path_factory):
    if not (REAL / "handeye_rwhe_kuka2").is_dir():
        pytest.skip(f"{REAL / 'handeye_rwhe_kuka2'} is absent: the real KUKA hand-eye images are not on this machine")
    root = tmp_path_factory.mktemp("guide")
    repo = root / "repo"
    repo.mkdir()
    for name in LINKED:
        (repo / name).symlink_to(REPO / name)
    (root / "shared").mkdir()
    (root / "shared" / "real-data").symlink_to(REAL)
    env = {k: v for k, v in os.environ.items() if k != "VIRTUAL_ENV"}
    env["PATH"] = os.pathsep.join([str(REPO / ".venv" / "bin"), env.get("PATH", "")])
    outs = []
    for body in kuka_blocks():
        r = subprocess.run(["bash", "-e", "-o", "pipefail", "-c", body], cwd=repo, env=env, capture_output=True,
                           text=True, timeout=1800)
        outs.append(r)
        assert r.returncode == 0 and "Traceback" not in r.stderr, f"{body}\n{r.stdout}\n{r.stderr}"
    return repo, outs


def test_the_guide_shows_the_split_and_its_comparison():
    text = "\n".join(kuka_blocks())
    assert "../shared/real-data/handeye_rwhe_kuka2/RobotPosesVec.txt" in text and "/work/" not in text
    for cmd in ("robocal import images", "--exclude im_05,im_14,im_21,im_28", "--only im_05,im_14,im_21,im_28",
                "robocal run kuka-train.mcap", "robocal evaluate runs/kuka-train kuka-test.mcap",
                "benchmarks/bench_handeye.py --run runs/kuka-train --test kuka-test.mcap"):
        assert cmd in text, cmd


def test_import_run_evaluate_on_the_held_out_images(guide_run):
    repo, _ = guide_run
    ev = json.loads((repo / "runs" / "kuka-test" / "evaluation.json").read_text())
    r = ev["recordings"][0]
    assert r["measure"] == "camera" and r["residual_unit"] == "px" and r["images"] == 4 and r["n"] == 4 * 24 * 17
    assert sorted(r["groups"]) == ["im_05.bmp", "im_14.bmp", "im_21.bmp", "im_28.bmp"]
    assert 0.3 < r["rms_2d_px"] < 1.3  # px, the robot's pose error floors it
    assert r["rms_axis_px"] == pytest.approx(r["rms_2d_px"] / 2**0.5, rel=0.15)
    res = json.loads((repo / "runs" / "kuka-train" / "results.json").read_text())
    assert res["summary"]["n_measurements"] == 12 * 24 * 17 and res["summary"]["residual_unit"] == "px"
    assert "error" not in res["summary"]


def test_robocal_beats_every_opencv_method_held_out(guide_run):
    repo, _ = guide_run
    out = json.loads((repo / "handeye-split.json").read_text())
    assert out["images"]["held_out"] == ["im_05.bmp", "im_14.bmp", "im_21.bmp", "im_28.bmp"]
    assert len(out["images"]["fitted"]) == 12
    m = out["methods"]
    ours = m.pop("robocal")
    ev = json.loads((repo / "runs" / "kuka-test" / "evaluation.json").read_text())["recordings"][0]
    assert ours["reprojection_rms_2d_px"] == pytest.approx(ev["rms_2d_px"], rel=1e-9)  # evaluate's own figure
    assert ours["check_rms_2d_px"] == pytest.approx(ev["rms_2d_px"], rel=1e-6)  # and the comparison's code agrees
    assert {"TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS", "RWHE_SHAH", "RWHE_LI"} <= set(m)
    for name, v in m.items():
        assert ours["reprojection_rms_2d_px"] < v["reprojection_rms_2d_px"], (name, ours, v)
        assert ours["board_rms_mm"] < v["board_rms_mm"], (name, ours, v)


def test_the_stated_hand_eye_sigma_is_the_image_jackknife(guide_run):
    repo, _ = guide_run
    he = json.loads((repo / "runs" / "kuka-train" / "results.json").read_text())["summary"]["hand_eye"]
    fit = json.loads((repo / "runs" / "kuka-train" / "identify" / "fit.json").read_text())
    assert set(he) == {"tool.x", "tool.y", "tool.z", "tool.roll", "tool.pitch", "tool.yaw"}
    for name, v in he.items():
        i = fit["names"].index(name)
        assert v["sigma_kind"] == "image jackknife" and v["sigma"] == pytest.approx(fit["std"][i])
        assert v["sigma"] >= fit["extra"]["jackknife_sigma"][name]  # jackknife + the independent part
        assert v["sigma"] > 3 * v["sigma_independent"], (name, v)  # corners of an image share its pose error
    assert 0.2e-3 < he["tool.x"]["sigma"] < 5e-3  # m: the order the spread of split estimates shows
    html = (repo / "runs" / "kuka-train" / "report.html").read_text()
    assert "jackknife" in html and "σ independent" in html
