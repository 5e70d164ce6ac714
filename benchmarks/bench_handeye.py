"""Camera + hand-eye on real images: robocal's joint fit against OpenCV's two-step calibrations.

Data: ../shared/real-data/handeye_rwhe_kuka2 (16 images 1920×1200 of a 24×17-corner chessboard, 15 mm
squares, eye-in-hand on a KUKA; flange poses measured by the robot, RobotPosesVec.txt).  Two protocols,
every method on the same detections and the same held-out images:

* ``--run RUN --test REC``: the split of the camera guide — robocal's calibration is the one `robocal run`
  made (RUN, on its own recording), applied to the held-out recording REC without refitting (what `robocal
  evaluate` reports); OpenCV's calibrateCamera (4, 5 and 8 distortion terms) + each calibrateHandEye /
  calibrateRobotWorldHandEye method fitted on RUN's recording's detections and judged on REC's images;
* k-fold (default): the images imported once (`robocal import images`), `--folds`-fold splits repeated
  `--repeats` times, robocal's joint fit (as `robocal run` identifies, registration + k3) refitted per split.

Figures (`pipeline.camera.compare`): held-out reprojection — the board's corners through the robot's pose
alone — as the RMS of the 2-D error (px; per axis under its own name) and the held-out board centre's
distance from the calibrated board position in the base frame (mm).

σ check (k-fold): the spread of robocal's hand-eye estimates over the splits against its stated σ (the
image jackknife).  The training sets share images (each holds m of N), so the spread of a subset estimate is
σ_m·sqrt(1 − m/N) (delete-d jackknife); the printed ratio is spread / that (≈ 1: honest).

    .venv/bin/python benchmarks/bench_handeye.py --run runs/kuka-train --test kuka-test.mcap [--json out.json]
    .venv/bin/python benchmarks/bench_handeye.py [--folds 4 --repeats 2] [--gls] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

DATA = ROOT.parent / "shared" / "real-data" / "handeye_rwhe_kuka2"
TARGET = "chessboard:24x17:0.015"
HELD_OUT = "im_05,im_14,im_21,im_28"  # the camera guide's split: 12 images fitted, these 4 held out
OPENCV_DIST = (4, 5, 8)  # OpenCV's calibrateCamera with k1 k2 p1 p2 (+ k3) (+ k4–k6): each method at its best


def load(folder: Path, work: Path, n_dist: int = 5):
    """Import the folder as a user would (`robocal import images`, the robot's RobotPosesVec.txt as shipped),
    then read the recording back: (model, table)."""
    from typer.testing import CliRunner

    from pipeline.cli import app, load_commands
    from pipeline.recording.reader import read_recording
    from pipeline.systems import urdf_robot

    load_commands(["import"])
    rec = work / "kuka.mcap"
    res = CliRunner().invoke(app, ["import", "images", str(folder), "--target", TARGET, "--poses",
                                   str(folder / "RobotPosesVec.txt"), "--out", str(rec),
                                   "--distortion-terms", str(n_dist)])
    if res.exit_code != 0:
        raise SystemExit(f"import failed: {res.output}")
    return urdf_robot.load(read_recording(rec))


def split_compare(run_dir: Path, test_rec: Path) -> dict:
    """The guide's protocol (module docstring): {"methods": {name: figures}, "images": {fitted, held_out}}.
    robocal's figures are those of `robocal evaluate` (the run's calibration applied, nothing refitted)."""
    from dataclasses import replace

    from pipeline.camera.compare import frames_of, held_out, opencv_methods
    from pipeline.evaluate.apply import evaluate
    from pipeline.evaluate.calibrated import read_calibrated
    from pipeline.recording.reader import read_recording
    from pipeline.systems import urdf_robot

    cal = read_calibrated(run_dir)
    train_path = Path(cal.recording)
    if not train_path.is_file():
        raise SystemExit(f"{train_path}: the run's recording is not there (run this from where `robocal run` ran)")
    model, train = urdf_robot.load(read_recording(train_path))
    rec = read_recording(test_rec)
    _, test = urdf_robot.load(rec)
    ev = evaluate(cal, [rec])[0]  # exactly what `robocal evaluate` reports
    m = replace(model, n_dist=int(cal.campaign.get("n_dist", model.n_dist)))
    x = np.asarray(cal.x, float)
    ours = held_out(m, x, *frames_of(m, x), test)
    out = {"robocal": {"reprojection_rms_2d_px": ev["rms_2d_px"], "reprojection_rms_px": ev["rms_axis_px"],
                       "board_rms_mm": ours["board_rms_mm"], "check_rms_2d_px": ours["reprojection_rms_2d_px"]}}
    for nd in OPENCV_DIST:
        mo = replace(model, n_dist=nd)
        for name, (k, X, Y) in opencv_methods(mo, train, nd).items():
            h = held_out(mo, mo.nominal(), k, X, Y, test)
            fig = {"reprojection_rms_2d_px": h["reprojection_rms_2d_px"], "reprojection_rms_px": h["reprojection_rms_px"],
                   "board_rms_mm": h["board_rms_mm"], "distortion_terms": nd}
            if name not in out or fig["reprojection_rms_2d_px"] < out[name]["reprojection_rms_2d_px"]:
                out[name] = fig
    labels = lambda t: sorted(set(np.asarray(t["label"]).astype(str)))  # noqa: E731
    return {"methods": out, "images": {"fitted": labels(train), "held_out": labels(test)}}


def compare(model, data, folds: int = 4, repeats: int = 2, seed: int = 0, gls: bool = False, sigma: bool = True,
            progress=print) -> dict:
    """Every method on every split: {"methods": {name: {reprojection_rms_px, board_rms_mm}}, "hand_eye": …}.
    robocal: its joint least-squares fit (`fit`, as `robocal run` identifies); with `gls` also the
    refit under the per-image random-effects model (robocal-gls).  With `sigma`: robocal's hand-eye σ
    by the image jackknife on all images against the spread of the split estimates."""
    from pipeline.camera.compare import frames_of, held_out, image_splits, opencv_methods, split_rows
    from pipeline.camera.uncertainty import clustered_fit, image_jackknife
    from pipeline.identify.complexity import fixed_for
    from pipeline.identify.least_squares import FitOptions, fit

    n_img = len(np.unique(data["image"]))
    splits = image_splits(n_img, folds, repeats, seed)
    opts = FitOptions(fixed=fixed_for(model, ["registration", "lens k3"]), before=False)
    res: dict[str, list] = {}
    board: dict[str, list] = {}
    he = []
    names = model.parameter_names()
    it = names.index("tool.x")
    for s, test in enumerate(splits):
        train, held = split_rows(data, test)
        t0 = time.perf_counter()
        f0 = fit(model, train, opts)
        cands = {"robocal": frames_of(model, f0.x)}
        if gls:
            cands["robocal-gls"] = frames_of(model, clustered_fit(model, train, opts)[0].x)
        cands |= opencv_methods(model, train, model.n_dist)
        for name, (k, X, Y) in cands.items():
            h = held_out(model, f0.x, k, X, Y, held)
            res.setdefault(name, []).append(h["residuals"])
            board.setdefault(name, []).append(h["board_mm"])
        he.append(f0.x[it:it + 6])
        progress(f"split {s + 1}/{len(splits)}: held-out images {test.tolist()}, robocal {time.perf_counter() - t0:.1f} s")
    methods = {n: {"reprojection_rms_2d_px": float(np.sqrt(np.mean(np.sum(np.concatenate(res[n]) ** 2, axis=1)))),
                   "reprojection_rms_px": float(np.sqrt(np.mean(np.concatenate(res[n]) ** 2))),
                   "board_rms_mm": float(np.sqrt(np.mean(np.concatenate(board[n]) ** 2)))} for n in res}
    out = {"methods": methods, "n_images": n_img, "splits": len(splits), "held_out_per_split": n_img // folds}
    if sigma:  # a subset of m of N images spreads about σ_N·sqrt(N/m − 1) around the mean (delete-d jackknife)
        f = fit(model, data, opts)
        sig, _ = image_jackknife(model, data, f.x, f.free)
        est = np.array(he)
        spread = est.std(axis=0, ddof=1)
        m = n_img - n_img // folds
        out["hand_eye"] = {k: {"estimate": float(f.x[it + j]), "jackknife_sigma": float(sig[it + j]),
                               "iid_sigma": float(f.std[it + j]), "spread_over_splits": float(spread[j]),
                               "ratio": float(spread[j] / (sig[it + j] * np.sqrt(n_img / m - 1)))}
                           for j, k in enumerate(names[it:it + 6])}
    return out


def _table(methods: dict) -> None:
    print(f"{'method':14s} {'held-out reprojection, RMS of the 2-D error px':>47s} {'per axis px':>12s} "
          f"{'board in base mm':>17s}")
    for n, v in sorted(methods.items(), key=lambda kv: kv[1]["reprojection_rms_2d_px"]):
        extra = f"  ({v['distortion_terms']} distortion terms)" if "distortion_terms" in v else ""
        print(f"{n:14s} {v['reprojection_rms_2d_px']:47.3f} {v['reprojection_rms_px']:12.3f} "
              f"{v['board_rms_mm']:17.3f}{extra}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", type=Path, help="a `robocal run` folder (the guide's split: with --test)")
    ap.add_argument("--test", type=Path, help="the held-out recording (robocal import images --only …)")
    ap.add_argument("--folds", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--gls", action="store_true", help="also the random-effects GLS refit (robocal-gls)")
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    t0 = time.perf_counter()
    if a.run is not None or a.test is not None:
        if a.run is None or a.test is None:
            raise SystemExit("--run and --test go together")
        out = split_compare(a.run, a.test)
        print(f"fitted on {len(out['images']['fitted'])} images, held out: {', '.join(out['images']['held_out'])} "
              f"({time.perf_counter() - t0:.0f} s); OpenCV at its best of {', '.join(map(str, OPENCV_DIST))} "
              "distortion terms per method")
        _table(out["methods"])
        best = min((v["reprojection_rms_2d_px"], n) for n, v in out["methods"].items() if n != "robocal")
        print(f"robocal {out['methods']['robocal']['reprojection_rms_2d_px']:.3f} px against the best OpenCV method "
              f"({best[1]}) {best[0]:.3f} px")
        if a.json:
            a.json.write_text(json.dumps(out, indent=2))
        return
    if not DATA.is_dir():
        print(f"skipped: {DATA} is absent (real KUKA hand-eye images; see docs/guide/camera.md)")
        return
    with tempfile.TemporaryDirectory() as tmp:
        model, data = load(DATA, Path(tmp))
    out = compare(model, data, a.folds, a.repeats, gls=a.gls)
    print(f"\n{out['n_images']} images, {out['splits']} splits holding out {out['held_out_per_split']} images each "
          f"({time.perf_counter() - t0:.0f} s)")
    _table(out["methods"])
    print("\nrobocal hand-eye (flange → camera): σ by the image jackknife (all images) against the spread of "
          "the split estimates (expected σ·sqrt(N/m − 1))")
    for k, v in out["hand_eye"].items():
        unit = "mm" if k[-1] in "xyz" else "mrad"
        print(f"  {k:11s} {v['estimate']:+.5f}  σ {v['jackknife_sigma'] * 1e3:.3f} {unit} "
              f"(independent-corner σ̂²(JᵀJ)⁻¹: {v['iid_sigma'] * 1e3:.3f})  spread {v['spread_over_splits'] * 1e3:.3f} "
              f"{unit}  spread / expected {v['ratio']:.2f}")
    if a.json:
        a.json.write_text(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
