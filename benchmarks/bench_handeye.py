"""Camera + hand-eye on real images: robocal's joint fit against OpenCV's two-step calibrations.

Data: /work/shared/real-data/handeye_rwhe_kuka2 (16 images 1920×1200 of a 24×17-corner
chessboard, 15 mm squares, eye-in-hand on a KUKA; flange poses measured by the robot).  The
images go through `robocal import images` (detection, recording); every method then sees the
same detections and the same held-out images: `--folds`-fold splits of the images, repeated
`--repeats` times.  Figures (`pipeline.camera.compare`): held-out reprojection RMS (px) and the
held-out board centre's distance from the calibrated board position in the base frame (mm).

σ check: the spread of robocal's hand-eye estimates over the splits against its stated σ.  The
training sets share images (each holds m of N), so the spread of a subset estimate is
σ_m·sqrt(1 − m/N) (delete-d jackknife); the printed ratio is spread / that (≈ 1: honest).

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

DATA = Path("/work/shared/real-data/handeye_rwhe_kuka2")
TARGET = "chessboard:24x17:0.015"


def kuka_pose_csv(folder: Path, out: Path) -> Path:
    """RobotPosesVec.txt (row-major 4×4 T_base_flange per line, line NN ↔ im_NN) → a pose CSV."""
    from scipy.spatial.transform import Rotation

    rows = np.loadtxt(folder / "RobotPosesVec.txt")
    lines = ["image,x,y,z,qx,qy,qz,qw"]
    for i, r in enumerate(rows):
        T = r.reshape(4, 4)
        q = Rotation.from_matrix(T[:3, :3]).as_quat()
        lines.append(f"im_{i + 1:02d}," + ",".join(repr(float(v)) for v in (*T[:3, 3], *q)))
    out.write_text("\n".join(lines) + "\n")
    return out


def load(folder: Path, work: Path, n_dist: int = 5):
    """Import the folder as a user would, then read the recording back: (model, table)."""
    from typer.testing import CliRunner

    from pipeline.cli import app, load_commands
    from pipeline.recording.reader import read_recording
    from pipeline.systems import urdf_robot

    load_commands(["import"])
    rec = work / "kuka.mcap"
    res = CliRunner().invoke(app, ["import", "images", str(folder), "--target", TARGET, "--poses",
                                   str(kuka_pose_csv(folder, work / "poses.csv")), "--out", str(rec),
                                   "--distortion-terms", str(n_dist)])
    if res.exit_code != 0:
        raise SystemExit(f"import failed: {res.output}")
    return urdf_robot.load(read_recording(rec))


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
    methods = {n: {"reprojection_rms_px": float(np.sqrt(np.mean(np.concatenate(res[n]) ** 2))),
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--folds", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--gls", action="store_true", help="also the random-effects GLS refit (robocal-gls)")
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    if not DATA.is_dir():
        print(f"skipped: {DATA} is absent (real KUKA hand-eye images; see docs/guide/camera.md)")
        return
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        model, data = load(DATA, Path(tmp))
    out = compare(model, data, a.folds, a.repeats, gls=a.gls)
    print(f"\n{out['n_images']} images, {out['splits']} splits holding out {out['held_out_per_split']} images each "
          f"({time.perf_counter() - t0:.0f} s)")
    print(f"{'method':14s} {'held-out reproj px':>19s} {'board in base mm':>17s}")
    for n, v in sorted(out["methods"].items(), key=lambda kv: kv[1]["reprojection_rms_px"]):
        print(f"{n:14s} {v['reprojection_rms_px']:19.3f} {v['board_rms_mm']:17.3f}")
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
