"""Real measured data of real robots (../shared/real-data/): import, calibrate, held-out figures.

Per dataset: rows, parameters identified, RMS before (registration only: instrument frame and
target fitted, nominal joints), RMS after, held-out RMS by k-fold (each fold refitted, the
model's groups selected inside each training set), and the peers' split — every 5th row held
out, the rest fitted (selection run on the fitted rows only) — for registration only and for
robocal.  Figures are 3-D RMS (the norm of each point's position error; for poses the position
part) in mm.  Peer figures (same data, every 5th row held out, registration only → peer):
TIAGo 5.59 → 5.24 mm, UR10e 4.86 → 6.70 mm; MUKCa on panda_1: 7.79 → 0.347 mm (mean absolute).

    python benchmarks/bench_real_data.py [--only tiago,ur10,mate,panda] [--folds 5]
    python benchmarks/bench_real_data.py --protocols tiago-sessions,mukca   # the peers' own protocols
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pipeline.identify.complexity import fixed_for, select
from pipeline.identify.least_squares import FitOptions, fit
from pipeline.identify.model import n_rows, take
from pipeline.recording.reader import read_recording
from pipeline.systems.registry import detect

REAL = Path(__file__).resolve().parents[2] / "shared" / "real-data"
if not REAL.is_dir():
    REAL = Path("/work/shared/real-data")
PEERS = {"tiago": "5.59 → 5.24 (FIGAROH)", "ur10": "4.86 → 6.70 (FIGAROH)", "mate": "—",
         "panda": "7.79 → 0.347 mean abs. (MUKCa)"}


def import_args(name: str, out: Path) -> list[str]:
    """`robocal import csv` arguments of each dataset (the README's commands)."""
    R = REAL
    if name == "tiago":
        d = R / "figaroh_tiago_mocap"
        return [str(d / "qualysis_base_hand_calibration.csv"), "--urdf", str(d / "tiago_48_schunk.urdf"),
                "--root", "base_footprint", "--tip", "wrist_ft_tool_link", "--measure", "point",
                "--position-cols", "x1,y1,z1", "--out", str(out)]
    if name == "ur10":
        d = R / "figaroh_ur10_pose"
        return [str(d / "calibration.csv"), "--urdf", str(d / "ur10_robot.urdf"), "--root", "base_link",
                "--tip", "tool0", "--measure", "pose", "--position-cols", "x1,y1,z1",
                "--orientation-cols", "phix1,phiy1,phiz1", "--out", str(out)]
    if name == "mate":
        d = R / "figaroh_mate_planes"
        return [str(d / f"10_points_{a}.csv") for a in "xyz"] + [
            "--urdf", str(d / "mate.urdf"), "--root", "Base", "--tip", "end_effector", "--measure", "plane",
            "--joint-units", "deg", "--plane", "10_points_x:1,0,0:x1", "--plane", "10_points_y:0,1,0:y1",
            "--plane", "10_points_z:0,0,1:z1", "--out", str(out)]
    d = R / "mukca_panda"
    places = ("back-high", "front", "right")
    files = [str(d / "data" / "panda_1" / p / f"hole_{k}.csv") for p in places for k in (0, 1)]
    return files + ["--urdf", str(d / "urdf" / "panda.urdf"), "--root", "panda_link0", "--tip", "ball_link",
                    "--measure", "coincidence", "--group-from", "parent/file",
                    "--columns", ",".join(f"panda_joint{i}" for i in range(1, 8))] + \
        [a for p in places for a in ("--distance", f"{p}/hole_0:{p}/hole_1:0.05")] + ["--out", str(out)]


def rms3(r: np.ndarray) -> float:
    """3-D RMS of the position part of residuals (n, k)."""
    return float(np.sqrt(np.mean(np.sum(r[:, :3] ** 2, axis=1))))


def holdout(model, data, train: np.ndarray, test: np.ndarray, folds: int, registration_only: bool) -> np.ndarray:
    """Residuals on `test` of a model fitted on `train` (groups selected on `train` alone)."""
    d_train = take(data, train)
    if registration_only:
        opts = FitOptions(fixed=fixed_for(model, ["registration"]), before=False)
    else:
        sel = select(model, d_train, k=folds)
        opts = FitOptions(fixed=sel.fixed, before=False)
    f = fit(model, d_train, opts)
    return model.residuals(f.x, take(data, test))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", default="tiago,ur10,mate,panda")
    ap.add_argument("--folds", type=int, default=5)
    ap.add_argument("--protocols", default="", help="tiago-sessions,mukca: the peers' own held-out protocols "
                    "(benchmarks/peer_protocols.py) instead of the table above")
    ap.add_argument("--run-timing", action="store_true", help="--protocols tiago-sessions: also time whole "
                    "`robocal run`s of the training session (default and shrinkage; about a minute)")
    ap.add_argument("--models", default="registration only,groups,all,shrinkage rigid,shrinkage",
                    help="model choices of --protocols (Panda's groups selection costs minutes of CPU)")
    ap.add_argument("--mukca-train", default="front_center", help="placement fitted (--protocols mukca)")
    ap.add_argument("--mukca-robot", default="panda_2", help="MUKCa unit (--protocols mukca): panda_2 (MUKCa's "
                    "calibrated URDF published) or panda_1 (--mukca-train front)")
    a = ap.parse_args()
    if not REAL.is_dir():
        sys.exit(f"real data not found at {REAL}")
    if a.protocols:
        import peer_protocols as pp

        choices = tuple(c.strip() for c in a.models.split(","))
        with tempfile.TemporaryDirectory() as tmp:
            if "tiago-sessions" in a.protocols:
                pp.tiago(REAL, Path(tmp), choices, a.run_timing)
            if "mukca" in a.protocols:
                pp.mukca(REAL, Path(tmp), choices, a.mukca_train, a.mukca_robot)
        return
    robocal = str(Path(sys.executable).parent / "robocal")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in a.only.split(","):
            rec_path = Path(tmp) / f"{name}.mcap"
            subprocess.run([robocal, "import", "csv", *import_args(name, rec_path)], check=True,
                           capture_output=True)
            rec = read_recording(rec_path)
            model, data = detect(rec).load(rec)
            n = n_rows(data)
            touch = np.asarray(data.get("kind", np.zeros(n, int))) == 0  # coincidence: distance rows always fitted
            t0 = time.perf_counter()
            sel = select(model, data, k=a.folds)
            f = fit(model, data, FitOptions(fixed=sel.fixed))
            t_fit = time.perf_counter() - t0
            before = rms3(model.residuals(model.uncalibrated(data), data)[touch])
            after = rms3(f.residuals_after[touch])
            # k-fold over rows, the selection repeated inside each training set
            idx = np.flatnonzero(touch)
            rng = np.random.default_rng(0)
            fold = np.empty(n, int)
            fold[idx] = rng.permutation(idx.size) % a.folds
            kf = np.full((n, model.residual_dim), np.nan)
            kf_reg = np.full((n, model.residual_dim), np.nan)
            for k in range(a.folds):
                test = idx[fold[idx] == k]
                train = np.setdiff1d(np.arange(n), test)
                kf[test] = holdout(model, data, train, test, a.folds, False)
                kf_reg[test] = holdout(model, data, train, test, a.folds, True)
            every5 = idx[::5]
            train5 = np.setdiff1d(np.arange(n), every5)
            e5 = rms3(holdout(model, data, train5, every5, a.folds, False))
            e5_reg = rms3(holdout(model, data, train5, every5, a.folds, True))
            rows.append((name, int(touch.sum()), f"{int(f.free.sum())}/{len(f.names)}", before, after,
                         rms3(kf_reg[touch]), rms3(kf[touch]), e5_reg, e5, t_fit, ",".join(sel.kept[1:]) or "—"))
            print(f"{name}: done in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    hdr = ("dataset", "rows", "identified", "before (reg.)", "after", "k-fold reg.", "k-fold robocal",
           "every-5th reg.", "every-5th robocal", "select+fit s", "groups kept beyond registration")
    print("| " + " | ".join(hdr) + " |")
    print("|" + "---|" * len(hdr))
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} | " + " | ".join(f"{v * 1e3:.3f}" for v in r[3:9])
              + f" | {r[9]:.2f} | {r[10]} |")
    print("\nmm, 3-D RMS of position errors; peers (every 5th held out): "
          + "; ".join(f"{k} {v}" for k, v in PEERS.items()))


if __name__ == "__main__":
    main()
