"""Real measured data of real robots (../shared/real-data/): import, calibrate, held-out figures.

Per dataset: rows, parameters identified, RMS before (registration only: instrument frame and
target fitted, nominal joints), RMS after, held-out RMS by k-fold (each fold refitted, the
model's groups selected inside each training set), and the peers' split — every 5th row held
out, the rest fitted (selection run on the fitted rows only) — for registration only and for
robocal.  Figures are 3-D RMS (the norm of each point's position error; for poses the position
part) in mm.  Peer figures (same data, every 5th row held out, registration only → peer):
TIAGo 5.59 → 5.24 mm, UR10e 4.86 → 6.70 mm; MUKCa on panda_1: 7.79 → 0.347 mm (mean absolute).

    python benchmarks/bench_real_data.py [--only tiago,ur10,mate,panda] [--folds 5]
    python benchmarks/bench_real_data.py --choice shrinkage --run-timing   # robocal run's default on imports
    python benchmarks/bench_real_data.py --protocols tiago-sessions,mukca   # the peers' own protocols
    python benchmarks/bench_real_data.py --protocols every5 --figaroh-python ../figaroh-venv/bin/python
    python benchmarks/bench_real_data.py --protocols every5 --only talos --talos DIR [--figaroh-python …]

`--protocols every5`: FIGAROH's every-5th splits (rows 0, 5, 10, … held out, the rest fitted; and the complement:
those rows fitted, the rest held out) with robocal's default (`robocal run`: shrinkage, its gravity terms) and,
with `--figaroh-python`, FIGAROH itself run on the same rows in its own venv (`benchmarks/figaroh_every5.py`),
side by side: RMS and mean of the norm of the 3-D error (MATE: of the plane-normal error), mm.
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
from pipeline.identify.shrinkage_fit import shrunk_fit
from pipeline.recording.reader import read_recording
from pipeline.systems.registry import detect, load_with_physics

REAL = Path(__file__).resolve().parents[2] / "shared" / "real-data"
TALOS: Path | None = None  # FIGAROH's TALOS example folder (--talos DIR: its CSV and URDF; not in the shared data)
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
    if name == "talos":  # FIGAROH's TALOS example: left arm and torso, a point on the gripper (mm-level contact data)
        return [str(TALOS / "talos_left_arm_02_10_contact.csv"), "--urdf", str(TALOS / "talos_full_v2.urdf"),
                "--root", "base_link", "--tip", "gripper_left_base_link", "--measure", "point",
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


def holdout(model, data, train: np.ndarray, test: np.ndarray, folds: int, registration_only: bool,
            choice: str = "groups") -> np.ndarray:
    """Residuals on `test` of a model fitted on `train` (groups selected, or the shrinkage scale and physics
    family chosen, on `train` alone)."""
    d_train = take(data, train)
    if choice == "shrinkage" and not registration_only:
        from pipeline.accuracy.prior import prior_sigma

        f, _, _ = shrunk_fit(model, d_train, FitOptions(prior_sigma=prior_sigma(model)[0]), k=2)
        return model.residuals(f.x, take(data, test))
    if registration_only:
        opts = FitOptions(fixed=fixed_for(model, ["registration"]), before=False)
    else:
        sel = select(model, d_train, k=folds)
        opts = FitOptions(fixed=sel.fixed, before=False)
    f = fit(model, d_train, opts)
    return model.residuals(f.x, take(data, test))


def chosen_fit(model, data, choice: str, folds: int):
    """(Fit on all rows by `choice`, what it chose, CPU s of one plain fit of the chosen model)."""
    from pipeline.accuracy.prior import prior_sigma

    if choice == "groups":
        sel = select(model, data, k=folds)
        c1 = time.process_time()
        f = fit(model, data, FitOptions(fixed=sel.fixed))
        return f, ",".join(sel.kept[1:]) or "—", time.process_time() - c1
    prior = prior_sigma(model)[0]
    f, s, _ = shrunk_fit(model, data, FitOptions(prior_sigma=prior), k=folds)
    groups = [g for g in model.groups() if not g.startswith("_")]
    on = tuple((s.physics or {}).get("terms", ()))
    c1 = time.process_time()  # one plain fit of the same model: every group free, the chosen physics terms
    fit(model, data, FitOptions(fixed=tuple(n for n in fixed_for(model, groups) if n not in on), before=False,
                                prior_sigma=prior))
    mu = "registration only" if np.isinf(s.mu_m) else f"μ {s.mu_m * 1e3:.3g} mm"
    what = f"{mu}, {s.dof:.1f} eff. parameters" + (f", physics {s.physics['chosen']}" if s.physics else "")
    return f, what, time.process_time() - c1


def figaroh_splits(names: list[str], tmp: Path, figaroh_python: str | None) -> None:
    """FIGAROH's every-5th splits: robocal's default and FIGAROH's (run by `figaroh_every5.py`) on the same rows."""
    robocal = str(Path(sys.executable).parent / "robocal")
    peer: dict = {}
    if figaroh_python:
        import json

        talos = ["--talos", str(TALOS)] if "talos" in names else []
        out = subprocess.run([figaroh_python, str(Path(__file__).with_name("figaroh_every5.py")), "--data", str(REAL),
                              "--only", ",".join(names), *talos], capture_output=True, text=True, check=True).stdout
        for line in out.splitlines():
            r = json.loads(line)
            peer.setdefault((r["dataset"], r["split"]), []).append(r)
    print("| dataset | split | rows fitted / held out | robocal RMS | robocal mean | FIGAROH (method): RMS / mean |")
    print("|---|---|---|---|---|---|")
    for name in names:
        rec_path = tmp / f"{name}.mcap"
        subprocess.run([robocal, "import", "csv", *import_args(name, rec_path)], check=True, capture_output=True)
        rec = read_recording(rec_path)
        model, data = load_with_physics(detect(rec), rec, "auto", None)
        for split, (train, test) in split_every5(n_rows(data)).items():
            e = holdout(model, data, train, test, 5, False, "shrinkage")
            norm = np.sqrt(np.sum(e[:, :3] ** 2, axis=1))
            cells = "; ".join(f"{r['method']}: {r['rms_3d_mm']:.3f} / {r['mean_3d_mm']:.3f}" if "error" not in r
                              else f"{r['method']}: refused ({r['error'][:60]})" for r in peer.get((name, split), []))
            print(f"| {name} | {split} | {train.size} / {test.size} | {rms3(e) * 1e3:.3f} | {norm.mean() * 1e3:.3f} | "
                  f"{cells or '—'} |", flush=True)


def split_every5(n: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{split: (fitted rows, held-out rows)}: rows 0, 5, 10, … held out (every5) or fitted (complement)."""
    every = np.arange(0, n, 5)
    rest = np.setdiff1d(np.arange(n), every)
    return {"every5": (rest, every), "complement": (every, rest)}


def run_timing(robocal: str, rec: Path, out: Path) -> tuple[float, float]:
    """(wall s, CPU s) of one whole `robocal run` (every stage, its default model choice) of `rec`."""
    import resource

    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([robocal, "run", str(rec), "--out", str(out)], check=True, capture_output=True)
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.perf_counter() - t0, (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", default="tiago,ur10,mate,panda")
    ap.add_argument("--folds", type=int, default=5)
    ap.add_argument("--protocols", default="", help="tiago-sessions,mukca: the peers' own held-out protocols "
                    "(benchmarks/peer_protocols.py) instead of the table above")
    ap.add_argument("--run-timing", action="store_true", help="also time whole `robocal run`s (every stage, wall and "
                    "CPU s): of each dataset (the table), or of the TIAGo training session (--protocols tiago-sessions: "
                    "the default and --model-choice groups)")
    ap.add_argument("--models", default="registration only,groups,all,shrinkage rigid,shrinkage",
                    help="model choices of --protocols (Panda's groups selection costs minutes of CPU)")
    ap.add_argument("--figaroh-python", default=None, help="--protocols every5: the Python of a venv with FIGAROH "
                    "installed (pip install figaroh): FIGAROH itself run on the same rows")
    ap.add_argument("--mukca-train", default="front_center", help="placement fitted (--protocols mukca)")
    ap.add_argument("--mukca-robot", default="panda_2", help="MUKCa unit (--protocols mukca): panda_2 (MUKCa's "
                    "calibrated URDF published) or panda_1 (--mukca-train front)")
    ap.add_argument("--choice", default="groups", help="groups (the selection, rigid model: the figures of "
                    "docs/guide/import-csv.md) or shrinkage (as `robocal run`'s default for imported URDF robots: its "
                    "gravity terms, scale and physics family chosen on each training set)")
    ap.add_argument("--talos", type=Path, default=None, help="--protocols every5: the folder of FIGAROH's TALOS example "
                    "(talos_left_arm_02_10_contact.csv, talos_full_v2.urdf; figaroh-examples `examples/talos`); "
                    "add talos to --only")
    a = ap.parse_args()
    global TALOS
    TALOS = a.talos
    if "talos" in a.only.split(",") and TALOS is None:
        sys.exit("--only talos needs --talos DIR (FIGAROH's TALOS example files)")
    if not REAL.is_dir():
        sys.exit(f"real data not found at {REAL}")
    if a.protocols:
        import peer_protocols as pp

        choices = tuple(c.strip() for c in a.models.split(","))
        with tempfile.TemporaryDirectory() as tmp:
            if "every5" in a.protocols:
                figaroh_splits([n for n in a.only.split(",") if n != "panda"], Path(tmp), a.figaroh_python)
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
            system = detect(rec)
            model, data = (system.load(rec) if a.choice == "groups" else load_with_physics(system, rec, "auto", None))
            n = n_rows(data)
            touch = np.asarray(data.get("kind", np.zeros(n, int))) == 0  # coincidence: distance rows always fitted
            t0, c0 = time.perf_counter(), time.process_time()
            f, kept, t_one = chosen_fit(model, data, a.choice, a.folds)
            t_fit, c_choice = time.perf_counter() - t0, time.process_time() - c0 - t_one
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
                kf[test] = holdout(model, data, train, test, a.folds, False, a.choice)
                kf_reg[test] = holdout(model, data, train, test, a.folds, True)
            every5 = idx[::5]
            train5 = np.setdiff1d(np.arange(n), every5)
            e5 = rms3(holdout(model, data, train5, every5, a.folds, False, a.choice))
            e5_reg = rms3(holdout(model, data, train5, every5, a.folds, True))
            timing = run_timing(robocal, rec_path, Path(tmp) / f"run-{name}") if a.run_timing else None
            rows.append((name, int(touch.sum()), f"{int(f.free.sum())}/{len(f.names)}", before, after,
                         rms3(kf_reg[touch]), rms3(kf[touch]), e5_reg, e5, t_fit, kept, c_choice, t_one, timing))
            print(f"{name}: done in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    hdr = ("dataset", "rows", "identified", "before (reg.)", "after", "k-fold reg.", "k-fold robocal",
           "every-5th reg.", "every-5th robocal", "choice+fit wall s", "model choice CPU s", "one plain fit CPU s",
           "choice / fit", "whole `robocal run` wall / CPU s", f"{a.choice}: chosen")
    print("| " + " | ".join(hdr) + " |")
    print("|" + "---|" * len(hdr))
    for r in rows:
        ratio = f"{r[11] / r[12]:.1f}×" if r[12] > 0 else "—"
        run = "—" if r[13] is None else f"{r[13][0]:.1f} / {r[13][1]:.1f}"
        print(f"| {r[0]} | {r[1]} | {r[2]} | " + " | ".join(f"{v * 1e3:.3f}" for v in r[3:9])
              + f" | {r[9]:.2f} | {r[11]:.2f} | {r[12]:.2f} | {ratio} | {run} | {r[10]} |")
    print("\nmm, 3-D RMS of position errors; peers (every 5th held out): "
          + "; ".join(f"{k} {v}" for k, v in PEERS.items()))


if __name__ == "__main__":
    main()
