"""A whole robot at the specialists' accuracy: a soft humanoid upper body (tests/independent_humanoid.py with
``whole=True``: no robocal code — both hands measured, a coupled torso, every arm joint compliant, lateral
compliance per normal at the torso, shoulders and elbows, stiffness that grows with the load, masses off the
URDF's), 2 × N postures drawn, the first N fitted by the default `robocal run` (tree route, physics auto) and the
other N applied by `robocal evaluate` without refitting — the held-out protocol of the makers of such robots.

Printed per seed: held-out mean and RMS of the norm of the 3-D error against the noise floor (mean √(8/π)·σ,
RMS √3·σ of isotropic noise σ per axis), the accuracy the run states for a new measurement and the ratio measured
/ stated, what the model choice kept (groups, physics terms, terms refused as negative, the prior's robot
class), and the time of each stage (wall; CPU of the whole run).

    python benchmarks/bench_whole_robot.py --seeds 0 --n 250            # the documented figures
    python benchmarks/bench_whole_robot.py --seeds 0 1 --n 250 --physics none   # geometry alone, for comparison
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
import independent_humanoid as hu  # noqa: E402

ROBOCAL = str(Path(sys.executable).with_name("robocal"))


def cli(*args) -> tuple[str, float, float]:
    """(stderr, wall s, CPU s of the child) of one robocal command."""
    t0, c0 = time.perf_counter(), os.times()
    r = subprocess.run([ROBOCAL, *map(str, args)], capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"robocal {' '.join(map(str, args[:2]))} failed:\n{r.stderr[-2000:]}")
    c1 = os.times()
    return r.stderr, time.perf_counter() - t0, (c1.children_user - c0.children_user) + (c1.children_system - c0.children_system)


def split(d: Path, n: int) -> tuple[Path, Path]:
    """The generator's table cut into the first `n` postures (fitted) and the rest (held out)."""
    lines = (d / "postures.csv").read_text().splitlines()
    (d / "fit.csv").write_text("\n".join([lines[0]] + lines[1:n + 1]) + "\n")
    (d / "test.csv").write_text("\n".join([lines[0]] + lines[n + 1:]) + "\n")
    return d / "fit.csv", d / "test.csv"


def one(seed: int, n: int, noise: float, tmp: Path, physics: str | None) -> dict:
    d = hu.write(tmp / f"s{seed}", seed=seed, n=2 * n, noise_m=noise, whole=True)
    recs = {}
    for part, csv in zip(("fit", "test"), split(d, n)):
        recs[part] = tmp / f"s{seed}_{part}.mcap"
        cli("import", "csv", csv, "--urdf", d / "humanoid.urdf", "--root", "base", "--tip", "left_hand=lx,ly,lz",
            "--tip", "right_hand=rx,ry,rz", "--coupled", "torso_j3=-torso_j1-torso_j2", "--measure", "point",
            "--out", recs[part])
    out = tmp / f"run{seed}"
    log, wall, cpu = cli("run", recs["fit"], "--out", out, *(("--physics", physics) if physics else ()))
    stages = {m.group(1): (float(m.group(2)), float(m.group(3) or "nan"))
              for m in re.finditer(r"^(\w+): ran in ([0-9.]+) s(?:, CPU ([0-9.]+) s)?", log, re.M)}
    cli("evaluate", out, recs["test"], "--out", out / "evaluate")
    ev = json.loads((out / "evaluate" / "evaluation.json").read_text())["recordings"][0]
    res = json.loads((out / "results.json").read_text())
    s = res["summary"]
    fit = json.loads((out / "identify" / "fit.json").read_text())
    refused = [p["name"] for p in fit["parameters"] if "estimated negative" in str(p.get("reason", ""))]
    kept = (fit.get("model_selection") or {}).get("kept_groups", [])
    return {"seed": seed, "mean": ev["mean_3d_m"], "rms": ev["rms_3d_m"], "stated": s.get("predicted_new_measurement_rms_3d_m") or ((res.get("stages") or {}).get("accuracy") or {})
            .get("summary", {}).get("new_measurement_rms_3d_m"),
            "floor_mean": np.sqrt(8 / np.pi) * noise, "floor_rms": np.sqrt(3) * noise, "wall": wall, "cpu": cpu,
            "stages": stages, "kept": kept, "refused": refused, "prior": (s.get("prior_class") or {}).get("class"),
            "physics": [t["parameter"] for t in (res.get("physics") or {}).get("terms", [])],
            "diagnosis": diagnosis(out)}


def diagnosis(out: Path) -> str:
    """Diagnose's status and what it named (one line), to compare runs."""
    p = out / "diagnose" / "diagnosis.json"
    if not p.exists():
        return "no diagnosis"
    d = json.loads(p.read_text())
    named = [f.get("effect") or f.get("name") for f in d.get("findings", []) if isinstance(f, dict)]
    return f"{d.get('status')}; findings: {', '.join(map(str, named)) or 'none'}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--n", type=int, default=250, help="postures fitted (as many held out), two hands each")
    ap.add_argument("--noise-m", type=float, default=2e-4)
    ap.add_argument("--physics", default=None, help="robocal run --physics (default: its default, auto)")
    ap.add_argument("--keep", type=Path, default=None, help="keep the recordings and runs in this folder")
    a = ap.parse_args()
    print(f"whole soft humanoid, {a.n} postures fitted / {a.n} held out × 2 hands, noise {a.noise_m * 1e3:.2f} mm "
          f"per axis, robocal run {'--physics ' + a.physics if a.physics else '(default)'} then robocal evaluate")
    print("seed | held-out mean / floor mm | RMS / floor mm | stated mm | measured/stated | run wall / CPU s | "
          "stages wall/CPU s")
    with tempfile.TemporaryDirectory() as tmp:
        if a.keep is not None:
            a.keep.mkdir(parents=True, exist_ok=True)
        for seed in a.seeds:
            r = one(seed, a.n, a.noise_m, a.keep or Path(tmp), a.physics)
            ratio = r["rms"] / r["stated"] if r["stated"] else float("nan")
            st = ", ".join(f"{k} {w:.1f}/{c:.1f}" for k, (w, c) in r["stages"].items())
            print(f"{seed:4d} | {r['mean'] * 1e3:.3f} / {r['floor_mean'] * 1e3:.3f} | {r['rms'] * 1e3:.3f} / "
                  f"{r['floor_rms'] * 1e3:.3f} | {(r['stated'] or float('nan')) * 1e3:.3f} | {ratio:.2f} | "
                  f"{r['wall']:.0f} / {r['cpu']:.0f} | {st}", flush=True)
            print(f"     kept: {', '.join(r['kept'])}; {len(r['physics'])} physics terms; refused as negative: "
                  f"{', '.join(r['refused']) or 'none'}; prior: {r['prior']}", flush=True)
            print(f"     diagnose: {r['diagnosis']}", flush=True)


if __name__ == "__main__":
    main()
