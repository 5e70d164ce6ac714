"""Whole robots with their physics: the independent humanoid generator (tests/independent_humanoid.py,
no robocal code: dual arm, coupled torso, whole-tree gravity, joint + lateral compliance at static
equilibrium) calibrated by the command line, per seed:

* the recovered joint stiffnesses against the truth (z = (ĉ − c)/σ̂ of the compliance c = 1/k);
* held-out RMS (per residual component, as robocal reports it): geometry only (physics held at 0, same
  folds), with the physics the model selection kept, `--physics none`, and the noise floor (σ per axis);
* the time of `robocal calibrate` with `--physics auto` (the default) and `--physics none`;
* with `--reading eccentricity|scale|coupling|backlash`, reading errors in the truth (`READING`): whether the
  model selection kept the family, and each recovered term against the truth (z = (v̂ − v)/σ̂);
* with `--bag` (backlash), the postures written as a ROS 2 bag (tests/independent_joint_bag.py: rosbags'
  writer, a JointState stream approaching each posture from the generator's side, no direction column):
  the directions robocal fits with come from the joint stream, not from `dir_<joint>` columns.

    python benchmarks/bench_physics.py --seeds 0 1 2 --n 150         # the documented figures
    python benchmarks/bench_physics.py --seeds 7 --n 120 --reading eccentricity
    python benchmarks/bench_physics.py --seeds 11 12 --n 120 --reading backlash --bag
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
import independent_humanoid as hu  # noqa: E402
import independent_joint_bag as jb  # noqa: E402

ROBOCAL = str(Path(sys.executable).with_name("robocal"))
READING = {"eccentricity": {"eccentricity": {"left_j3": (3e-3, -2e-3), "right_j3": (-2e-3, 2.5e-3)}},
           "scale": {"scale": {"left_j4": 4e-3, "right_j2": -3e-3}},
           "coupling": {"coupling": {"left_j3": ("left_j2", 8e-3), "right_j5": ("right_j4", -6e-3)}},
           "backlash": {"backlash": {"left_j2": 4e-3, "right_j4": 3e-3}}, "none": {}}
TOPICS = {"left_hand": "/mocap/left_hand", "right_hand": "/mocap/right_hand"}


def cli(*args) -> float:
    t0 = time.perf_counter()
    r = subprocess.run([ROBOCAL, *map(str, args)], capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"robocal {' '.join(map(str, args[:2]))} failed:\n{r.stderr[-2000:]}")
    return time.perf_counter() - t0


def bag_of(d: Path, out: Path) -> Path:
    """The generator's postures as a ROS 2 bag whose joint stream approaches each from its side."""
    lines = (d / "postures.csv").read_text().splitlines()
    col = {h: i for i, h in enumerate(lines[0].split(","))}
    rows = [[float(v) for v in ln.split(",")] for ln in lines[1:]]
    pick = lambda names: [[r[col[c]] for c in names] for r in rows]  # noqa: E731
    markers = {TOPICS["left_hand"]: pick(["lx", "ly", "lz"]), TOPICS["right_hand"]: pick(["rx", "ry", "rz"])}
    import numpy as np

    return jb.write_bag(out, hu.READ, np.array(pick(hu.READ)), np.array(pick([f"dir_{j}" for j in hu.READ])),
                        {k: np.array(v) for k, v in markers.items()})


def one(seed: int, n: int, noise: float, tmp: Path, reading: str = "none", bag: bool = False) -> dict:
    d = hu.write(tmp / f"s{seed}", seed=seed, n=n, noise_m=noise, **READING[reading])
    rec = tmp / f"s{seed}.mcap"
    if bag:
        cli("import", "ros2", bag_of(d, tmp / f"s{seed}.bag"), "--urdf", d / "humanoid.urdf", "--root", "base",
            "--coupled", "torso_j3=-torso_j1-torso_j2", "--measure-topic", f"left_hand={TOPICS['left_hand']}",
            "--measure-topic", f"right_hand={TOPICS['right_hand']}", "--out", rec)
    else:
        cli("import", "csv", d / "postures.csv", "--urdf", d / "humanoid.urdf", "--root", "base",
            "--tip", "left_hand=lx,ly,lz", "--tip", "right_hand=rx,ry,rz", "--coupled", "torso_j3=-torso_j1-torso_j2",
            "--measure", "point", "--out", rec)
    t_auto = cli("calibrate", rec, "--out", tmp / f"auto{seed}")
    t_none = cli("calibrate", rec, "--out", tmp / f"none{seed}", "--physics", "none")
    auto = json.loads((tmp / f"auto{seed}" / "results.json").read_text())
    none = json.loads((tmp / f"none{seed}" / "results.json").read_text())
    truth = json.loads((d / "truth.json").read_text())
    terms = {t["joint"]: t for t in auto["physics"]["terms"] if t["family"] == "joint-compliance"}
    z = {}
    for j, k in truth["stiffness_Nm_per_rad"].items():
        t = terms.get(j)
        if t and t["compliance_std_rad_per_Nm"]:
            z[j] = ((t["compliance_rad_per_Nm"] - 1 / k) / t["compliance_std_rad_per_Nm"], t["stiffness_Nm_per_rad"], k)
    p = {r["name"]: r for r in auto["parameters"]}
    truth_terms = {f"{j}.ecc_sin": a for j, (a, _) in truth["eccentricity"].items()} | \
        {f"{j}.ecc_cos": b for j, (_, b) in truth["eccentricity"].items()} | \
        {f"{j}.scale": v for j, v in truth["scale"].items()} | \
        {f"{j}.coupling": kappa for j, (_, kappa) in truth["coupling"].items()} | \
        {f"{j}.backlash": b for j, b in truth["backlash"].items()}
    zr = {k: ((p[k]["estimate"] - v) / p[k]["std"], p[k]["estimate"], v, p[k]["std"]) for k, v in truth_terms.items()
          if k in p and p[k]["identifiable"] and p[k]["std"]}
    return {"seed": seed, "z": z, "z_reading": zr, "groups": auto["model_selection"]["kept_groups"],
            "geometry_m": auto["physics"]["holdout_geometry_only_m"],
            "physics_m": auto["physics"]["holdout_with_physics_m"], "none_m": none["holdout_rms_m"],
            "floor_m": noise, "t_auto": t_auto, "t_none": t_none,
            "kept": [t["parameter"] for t in auto["physics"]["terms"]]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--n", type=int, default=150, help="postures per campaign (two hand markers each)")
    ap.add_argument("--noise-m", type=float, default=2e-4)
    ap.add_argument("--reading", choices=sorted(READING), default="none", help="reading errors in the truth")
    ap.add_argument("--bag", action="store_true", help="import a ROS 2 bag (directions from its joint stream)")
    a = ap.parse_args()
    print(f"humanoid, {a.n} postures × 2 hands, noise {a.noise_m * 1e3:.2f} mm per axis, reading errors: {a.reading}"
          + (", from a ROS 2 bag (directions from the joint stream)" if a.bag else ""))
    print("seed | held-out mm: geometry only | with physics | --physics none | floor | calibrate s: auto | none",
          flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for s in a.seeds:  # one line per seed as it finishes
            r = one(s, a.n, a.noise_m, Path(tmp), a.reading, a.bag)
            rows.append(r)
            print(f"{r['seed']:4d} | {r['geometry_m'] * 1e3:26.3f} | {r['physics_m'] * 1e3:12.3f} | "
                  f"{r['none_m'] * 1e3:14.3f} | {r['floor_m'] * 1e3:5.3f} | {r['t_auto']:17.1f} | {r['t_none']:4.1f}",
                  flush=True)
    print("\nrecovered stiffness (N·m/rad) vs truth, z = (ĉ − c)/σ̂ of the compliance")
    for r in rows:
        cells = [f"{j} {'≤0' if k_hat is None else f'{k_hat:.3g}'}/{k:.3g} z={zz:+.1f}"
                 for j, (zz, k_hat, k) in r["z"].items()]
        print(f"seed {r['seed']}: " + "; ".join(cells))
    zs = [zz for r in rows for zz, _, _ in r["z"].values()]
    if zs:
        print(f"\n|z| ≤ 2 for {sum(abs(v) <= 2 for v in zs)}/{len(zs)} recovered stiffnesses; "
              f"RMS z {(sum(v * v for v in zs) / len(zs)) ** 0.5:.2f}")
    for r in rows:
        print(f"seed {r['seed']} kept groups: {', '.join(r['groups'])}; {len(r['kept'])} physics terms")
        if r["z_reading"]:
            print("  reading terms (truth → estimate ± σ, z): " + "; ".join(
                f"{k} {v:.3g} → {v_hat:.3g} ± {sd:.2g} z={zz:+.1f}" for k, (zz, v_hat, v, sd) in r["z_reading"].items()))


if __name__ == "__main__":
    main()
