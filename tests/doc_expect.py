"""What the documentation's pages must reach when their ```sh blocks run (tests/doc_runner.py): checked in a page's
scratch folder after its last block — the figures a capability must reach on real data, the files a user would
look at."""

from __future__ import annotations

import csv
import json
import subprocess
from pathlib import Path

from doc_pages import REPO

def _json(path: Path) -> dict:
    return json.loads(path.read_text())


def _findings(diagnosis: Path) -> list[tuple[str, str]]:
    return [(f["effect"], f["location"]) for f in _json(diagnosis)["findings"]]


def _acquire(repo: Path):
    """The acquired drive-state recording diagnoses as its source: the true compliance, measured torque."""
    values = []
    for d in ("d_src", "d_acq"):
        (f,) = _json(repo / d / "diagnosis.json")["findings"]
        assert (f["effect"], f["location"], f["source"]) == ("joint_compliance", "shoulder_lift_joint", "measured torque")
        values.append(f["parameters"][0]["value"])
    assert abs(values[0] - 3e-6) < 3e-7 and abs(values[1] - values[0]) < 1e-4 * values[0], values
    assert (repo / "restored.mcap").stat().st_size > 0 and (repo / "runs/x/results.json").is_file()


def _compensate(repo: Path):
    rows = list(csv.DictReader((repo / "program.csv").open()))
    assert [r["status"] for r in rows] == ["ok"] * 3, rows
    assert max(float(r["correction_m"]) for r in rows) > 1e-3  # the calibrated robot needs its program corrected


def _diagnose(repo: Path):
    """Each example's injected effects found and named, nothing else."""
    assert _findings(repo / "DIR/diagnosis.json") == [("joint_compliance", "J2")]
    assert _findings(repo / "WARM/diagnosis.json") == [("thermal_drift", "temperature link2")]
    assert sorted(_findings(repo / "DELTA/diagnosis.json")) == [("backlash", "A2"), ("thermal_drift", "campaign")]


def _fleet(repo: Path):
    """Exactly the injected step flagged, on the robot and month it was injected; the cluster ran arc-01's first month."""
    robots = _json(repo / "fleet.json")["robots"]
    steps = {r: [(s["param"], s["recording"]) for s in f["steps"]] for r, f in robots.items()}
    assert steps == {"arc-01": [], "arc-02": [("J3.theta_offset", "arc-02/2026-02/campaign.mcap")]}, steps
    assert len((repo / "out-cluster/summary.csv").read_text().splitlines()) == 1 + 1


def _published(stated_mm: float, measured_m: float, what: str) -> None:
    """A figure the README states (to 0.01 mm, or 0.001 mm below 1 mm), measured again by the page's commands."""
    digits = 3 if stated_mm < 1 else 2
    assert round(measured_m * 1e3, digits) == stated_mm, (
        f"{what}: the commands give {measured_m * 1e3:.4f} mm where README.md states {stated_mm} mm — "
        "update README.md, the guide and this check together")


def _import_csv(repo: Path):
    """The README's figures of the four real datasets, through the guide's commands (import → run → evaluate)."""
    recs = {r["path"]: r for r in _json(repo / "runs/tiago-eval/evaluation.json")["recordings"]}
    for s, mm in (("2021-11-26", 2.82), ("2021-11-30-1403", 2.60), ("2021-11-30-1504", 2.40)):
        _published(mm, recs[f"tiago_{s}.mcap"]["rms_3d_m"], f"FIGAROH's TIAGo protocol, the recording of {s}")
    (ur10,) = _json(repo / "runs/ur10-eval/evaluation.json")["recordings"]
    _published(3.62, ur10["rms_3d_m"], "UR10e, every 5th row held out")
    (mate,) = _json(repo / "runs/mate-eval/evaluation.json")["recordings"]
    _published(1.91, mate["rms_normal_m"], "MATE, every 5th row held out (along the normals)")
    panda = _json(repo / "runs/panda_2-eval/evaluation.json")["recordings"]
    assert len(panda) == 8
    _published(0.429, sum(r["mean_3d_m"] for r in panda) / 8, "MUKCa's panda_2 protocol, mean over 8 placements")
    _beats_mukca(repo, {Path(r["path"]).name: r["mean_3d_m"] for r in panda})
    assert (repo / "runs/tiago/identify/model.urdf").is_file() and (repo / "runs/tiago-two/results.json").is_file()


def _beats_mukca(repo: Path, ours: dict[str, float]) -> None:
    """MUKCa's own protocol on panda_2: robocal's calibration (fitted on front_center by the guide's `robocal run`:
    shrinkage with whole sockets left out, the ball centre judged free vs known by them, as MUKCa frees its ball
    joint) at or below MUKCa's published calibrated URDF, evaluated by the same code, on every other placement, and
    far better than the nominal robot."""
    from pipeline.evaluate.apply import evaluate
    from pipeline.evaluate.calibrated import from_urdf
    from pipeline.recording.reader import read_recording

    ms = _json(repo / "runs/panda_2/identify/fit.json")["model_selection"]
    assert "holdout_per_group_m" in ms and 0 < ms["mu_m"] < 1, ms["method"]  # whole sockets left out; a finite μ
    assert ms["tool"] == "free" and ms["registration"] in ("anchored", "free")  # the left-out sockets judged them
    names = sorted(ours)
    recs = [read_recording(repo / n) for n in names]
    d = repo.parent / "shared" / "real-data" / "mukca_panda"
    figure = {u: [r["mean_3d_m"] for r in evaluate(from_urdf(d / u, "panda_link0", "ball_link", "coincidence"), recs)]
              for u in ("calibrated_urdf/panda_2/panda_calibrated.urdf", "urdf/panda.urdf")}
    for n, theirs, nominal in zip(names, *figure.values()):
        assert ours[n] <= theirs and ours[n] < 0.2 * nominal, (n, ours[n], theirs, nominal)


def _import_ros2(repo: Path):
    """Bags written by rosbags from the TIAGo sessions give the CSV import's held-out figure; every pose paired."""
    (ev,) = _json(repo / "runs/tiago-bag-eval/evaluation.json")["recordings"]
    _published(2.82, ev["rms_3d_m"], "the TIAGo recording of 2021-11-26, from a bag")
    assert _json(repo / "runs/tiago-bag/results.json")["summary"]["status"] in ("pass", "warn")
    r = subprocess.run([str(REPO / ".venv/bin/python"), "-c", "import sys; from pipeline.recording.reader import "
                        "read_recording; print(read_recording(sys.argv[1]).metadata['robocal.campaign']['ros2']['pairing']['n_paired'])",
                        str(repo / "ur10.mcap")], capture_output=True, text=True, timeout=120)
    assert r.stdout.strip() == "23", r.stderr


def _physics(repo: Path):
    """The humanoid's tree calibrated from its CSV (the bag imports the same 80 points), every program row solved."""
    summary = _json(repo / "runs/h/results.json")["summary"]
    assert summary["holdout_rms_3d_m"] < 1e-3 and summary["status"] != "fail", summary
    for program in ("program.csv", "program-up.csv"):
        rows = list(csv.DictReader((repo / program).open()))
        assert [r["status"] for r in rows] == ["ok"] * 5, (program, rows)


def _plan(repo: Path):
    """The two-stage campaign lands (the page: 98.3 % over 20 pools), calibrates, and its pty copy is complete."""
    ex = _json(repo / "T.json")["campaign_execution"]
    assert ex["planned"] == 50 and ex["land_rate"] >= 0.94, ex
    assert len([m for m in ex["misses"] if m["index"] >= 15]) <= 2, ex  # planned on the updated model, stage 2 lands
    c2 = _json(repo / "C2.json")
    assert c2["stage"] == 2 and c2["earlier_contacts"] >= 10, c2["stage"]
    assert _json(repo / "RUN1/results.json")["summary"]["status"] != "fail"


def _accuracy(repo: Path):
    """The map at the user's three points, the bound the page states for the jig grid passed the 0.25 mm tolerance."""
    acc = _json(repo / "runs/x/accuracy/accuracy.json")
    assert len(acc["map"]["points_m"]) == 3 and acc["status"] == "pass", acc["status"]
    assert (repo / "runs/y/results.json").is_file()


def _camera(repo: Path):
    """The KUKA images through the guide's commands: the held-out 2-D reprojection RMS (px, through the robot pose
    alone) beats every OpenCV hand-eye method on the same split, on both figures; the hand-eye σ the run states is
    the image jackknife's, not the independent-corner one."""
    (ev,) = _json(repo / "runs/kuka-test/evaluation.json")["recordings"]
    assert ev["measure"] == "camera" and ev["residual_unit"] == "px" and ev["images"] == 4 and ev["n"] == 4 * 24 * 17
    assert sorted(ev["groups"]) == ["im_05.bmp", "im_14.bmp", "im_21.bmp", "im_28.bmp"]
    assert 0.3 < ev["rms_2d_px"] < 1.3 and abs(ev["rms_axis_px"] / (ev["rms_2d_px"] / 2**0.5) - 1) < 0.15, ev
    res = _json(repo / "runs/kuka-train/results.json")
    assert res["summary"]["n_measurements"] == 12 * 24 * 17 and res["summary"]["residual_unit"] == "px"
    assert "error" not in res["summary"]
    out = _json(repo / "handeye-split.json")
    assert out["images"]["held_out"] == ["im_05.bmp", "im_14.bmp", "im_21.bmp", "im_28.bmp"]
    assert len(out["images"]["fitted"]) == 12
    methods = dict(out["methods"])
    ours = methods.pop("robocal")
    assert abs(ours["reprojection_rms_2d_px"] - ev["rms_2d_px"]) <= 1e-9 * ev["rms_2d_px"]  # evaluate's own figure
    assert abs(ours["check_rms_2d_px"] - ev["rms_2d_px"]) <= 1e-6 * ev["rms_2d_px"]  # the comparison's code agrees
    assert {"TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS", "RWHE_SHAH", "RWHE_LI"} <= set(methods)
    for name, v in methods.items():
        assert ours["reprojection_rms_2d_px"] < v["reprojection_rms_2d_px"], (name, ours, v)
        assert ours["board_rms_mm"] < v["board_rms_mm"], (name, ours, v)
    he = res["summary"]["hand_eye"]
    fit = _json(repo / "runs/kuka-train/identify/fit.json")
    assert set(he) == {"tool.x", "tool.y", "tool.z", "tool.roll", "tool.pitch", "tool.yaw"}
    for name, v in he.items():
        sigma = fit["std"][fit["names"].index(name)]
        assert v["sigma_kind"] == "image jackknife" and abs(v["sigma"] - sigma) <= 1e-6 * sigma, (name, v)
        assert v["sigma"] >= fit["extra"]["jackknife_sigma"][name]  # jackknife + the independent part
        assert v["sigma"] > 3 * v["sigma_independent"], (name, v)  # corners of an image share its pose error
    assert 0.2e-3 < he["tool.x"]["sigma"] < 5e-3  # m: the order the spread of split estimates shows
    html = (repo / "runs/kuka-train/report.html").read_text()
    assert "jackknife" in html and "σ independent" in html
    assert len(_json(repo / "P.json")["measurements"]) == 10  # the planned camera campaign: --select 10


EXPECT: dict = {
    "docs/guide/camera.md": _camera,
    "docs/guide/accuracy.md": _accuracy,
    "docs/guide/plan.md": _plan,
    "docs/guide/physics.md": _physics,
    "docs/guide/import-ros2.md": _import_ros2,
    "docs/guide/import-csv.md": _import_csv,
    "docs/guide/fleet.md": _fleet,
    "docs/guide/diagnose.md": _diagnose,
    "docs/guide/acquire.md": _acquire,
    "docs/guide/compensate.md": _compensate,
}
