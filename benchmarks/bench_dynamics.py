"""Dynamics identification on FIGAROH's TIAGo protocol, side by side: robocal vs FIGAROH vs the URDF as
drawn, per scored joint and pooled (N·m), on the frozen split and by contiguous-block cross-validation;
and the speed of filter + regressor + fit on 8 000 samples × 8 joints.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_dynamics.py
    PYTHONPATH=. .venv/bin/python benchmarks/bench_dynamics.py --figaroh ../figaroh-venv/bin/python \
        --figaroh-examples FIGAROH_EXAMPLES_CHECKOUT            # FIGAROH run by FIGAROH, side by side (minutes)
    PYTHONPATH=. .venv/bin/python benchmarks/bench_dynamics.py --figaroh-json FIGAROH.json   # a FIGAROH run's figures
    (--figaroh-modes train,split,cv chooses FIGAROH's runs; --figaroh-save FIGAROH.json keeps their figures)

Data: ../shared/real-data/figaroh_tiago_dynamics (training run `dynamic/`; the validation run
`calibration_slow/` where present).  Efforts are converted exactly as FIGAROH does (reduction ratio × kmotor,
the differential wrist τ6 = k(e7 − e6), τ7 = k(e6 + e7), the torso's 9.81 × subtree mass); arm_1–4 are fitted
and scored.  FIGAROH's figures: run by FIGAROH itself where a Python with `figaroh` and a figaroh-examples
checkout are given (`benchmarks/figaroh_tiago_dynamics.py`: its training fit on [921, 6791), the split, the same
contiguous blocks as robocal's cross-validation), else the split's as FIGAROH 1.0.2 gave them (fitted on
[921, 4900), predicting [4900, 6791) without refitting, raw converted effort at the recorded rate), and its
published held-out figure on `calibration_slow` (its README).  Then robocal's dynamics diagnosis of the run, and
the speed of filter + regressor + fit + diagnosis on 8 000 samples × 8 fitted joints.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import time
from pathlib import Path

import numpy as np

from pipeline.dynamics import effort as E
from pipeline.dynamics import identify as I
from pipeline.dynamics import rigid_body as RB
from pipeline.dynamics.crossval import blocks, train_rows
from pipeline.dynamics.signals import lowpass, sample_rate
from pipeline.importers.csv_effort import read_logs
from pipeline.models import urdf as U

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "real-data" / "figaroh_tiago_dynamics"
SCORED = ["arm_1_joint", "arm_2_joint", "arm_3_joint", "arm_4_joint"]
K = {"torso_lift_joint": 1.0, "arm_1_joint": 13.6, "arm_2_joint": 13.6, "arm_3_joint": -8.7, "arm_4_joint": -8.7,
     "arm_5_joint": 336 * -0.0613, "arm_6_joint": 336 * -0.0613, "arm_7_joint": 336 * -0.0613}
FIGAROH_SPLIT = {"arm_1_joint": 1.451, "arm_2_joint": 3.127, "arm_3_joint": 1.385, "arm_4_joint": 1.442,
                 "pooled": 1.992, "pooled arm_2–4": 2.143}
FIGAROH_NOMINAL_SPLIT = 5.410
FIGAROH_SLOW = {"arm_1_joint": 1.310, "arm_2_joint": 2.540, "arm_3_joint": 1.471, "arm_4_joint": 1.237,
                "pooled": 1.722, "pooled arm_2–4": 1.839}
FIGAROH_NOMINAL_SLOW = {"arm_1_joint": 3.187, "arm_2_joint": 7.838, "arm_3_joint": 3.122, "arm_4_joint": 2.858,
                        "pooled": 4.730, "pooled arm_2–4": 5.143}


def load(folder: str, desc, rb):
    L = read_logs(DATA / folder / "tiago_position.csv", desc, DATA / folder / "tiago_velocity.csv",
                  DATA / folder / "tiago_effort.csv")
    J = desc.joint_names
    doc = E.declaration(J, K, {"torso_lift_joint": RB.subtree_weight(rb, "torso_lift_joint")},
                        E.parse_mix(["arm_6_joint=-arm_6_joint+arm_7_joint", "arm_7_joint=arm_6_joint+arm_7_joint"],
                                    J), SCORED)
    return L["t_s"], L["q"], E.to_torque(L["effort"], doc, J), np.isin(J, SCORED)


def figures(r: np.ndarray) -> dict:
    out = dict(zip(SCORED, np.sqrt(np.mean(r**2, 0)).tolist()))
    out["pooled"] = float(np.sqrt(np.mean(r**2)))
    out["pooled arm_2–4"] = float(np.sqrt(np.mean(r[:, 1:] ** 2)))
    return out


def show(title: str, cols: dict[str, dict]) -> None:
    keys = [*SCORED, "pooled", "pooled arm_2–4"]
    print(f"\n{title}")
    print(f"{'':18s}" + "".join(f"{k:>16s}" for k in keys))
    for name, d in cols.items():
        print(f"{name:18s}" + "".join(f"{d[k]:16.3f}" if d.get(k) is not None else f"{'—':>16s}" for k in keys))


FIGAROH_PYTHON = Path(os.environ.get("FIGAROH_PYTHON", "../figaroh-venv/bin/python"))  # a FIGAROH venv beside the
# repository, or the one $FIGAROH_PYTHON names (used when present)


def figaroh_run(python: Path, examples: Path, *mode: str) -> dict:
    """One mode of benchmarks/figaroh_tiago_dynamics.py run by FIGAROH's Python (its JSON line)."""
    script = Path(__file__).with_name("figaroh_tiago_dynamics.py")
    w0 = time.perf_counter()
    r = subprocess.run([str(python), str(script), "--examples", str(examples), "--data", str(DATA), *mode],
                       capture_output=True, text=True, check=False, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    if r.returncode:
        raise SystemExit(f"FIGAROH run {' '.join(mode)} failed:\n{r.stderr[-2000:]}")
    doc = json.loads(r.stdout.strip().splitlines()[-1])
    print(f"  FIGAROH {' '.join(mode)}: {time.perf_counter() - w0:.0f} s wall", flush=True)
    return doc


def figaroh_figures(doc: dict) -> dict:
    return {**doc["per_joint"], "pooled": doc["pooled"], "pooled arm_2–4": doc["pooled_2_4"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--figaroh", type=Path, default=FIGAROH_PYTHON if FIGAROH_PYTHON.is_file() else None,
                    help="a Python with figaroh installed: run FIGAROH side by side (default: this box's venv)")
    ap.add_argument("--figaroh-examples", type=Path, default=os.environ.get("FIGAROH_EXAMPLES"),
                    help="a figaroh-examples checkout (env FIGAROH_EXAMPLES): FIGAROH's TiagoIdentification")
    ap.add_argument("--figaroh-json", type=Path, help="figures of an earlier FIGAROH run: {split: {per_joint, pooled, "
                    "pooled_2_4}, cv: {…}}")
    ap.add_argument("--figaroh-modes", default="train,split,cv",
                    help="FIGAROH runs to make, comma-separated: train (its published fit), split, cv (5 fits)")
    ap.add_argument("--figaroh-save", type=Path, help="write the FIGAROH runs' figures here (for --figaroh-json)")
    ap.add_argument("--no-diagnosis", action="store_true", help="skip the dynamics diagnosis of the run")
    ap.add_argument("--no-speed", action="store_true", help="skip the speed section (8 000 samples × 8 joints)")
    ap.add_argument("--quick", action="store_true", help="robocal on the split only (no FIGAROH run, no "
                    "cross-validation, diagnosis or speed)")
    args = ap.parse_args()
    if args.quick:
        args.figaroh = None  # FIGAROH's figures only from --figaroh-json
    if not (DATA / "dynamic" / "tiago_effort.csv").is_file():
        print(f"{DATA} is absent: nothing to compare")
        return
    desc = U.read(DATA / "tiago_48_hey5.urdf", "base_footprint", "arm_7_link")
    rb = RB.build(desc.urdf, desc.joint_names)
    t, q, tau, fit = load("dynamic", desc, rb)
    theirs = json.loads(args.figaroh_json.read_text()) if args.figaroh_json else {}
    if args.figaroh is not None and args.figaroh_examples is not None and not theirs:
        print("running FIGAROH (its own TIAGo identification, minutes per run) …", flush=True)
        modes = args.figaroh_modes.split(",")
        if "train" in modes:
            theirs["train"] = train = figaroh_run(args.figaroh, args.figaroh_examples, "train")
            print(f"  FIGAROH training fit on [921, 6791): {train['train_rmse']:.3f} N·m pooled arm_1–4, "
                  f"{train['n_base']} base parameters (published 0.884, 57)")
        if "split" in modes:
            theirs["split"] = figaroh_run(args.figaroh, args.figaroh_examples, "split")
        if "cv" in modes:
            theirs["cv"] = figaroh_run(args.figaroh, args.figaroh_examples, "cv", "5", "50")
        if args.figaroh_save:
            args.figaroh_save.write_text(json.dumps(theirs, indent=1))
    elif theirs:
        print(f"FIGAROH's figures from {args.figaroh_json} (a run of benchmarks/figaroh_tiago_dynamics.py)")
    else:
        print("FIGAROH not run here (give --figaroh PYTHON and --figaroh-examples CHECKOUT): its split figures as "
              "FIGAROH 1.0.2 gave them")

    # the frozen split: fit [921, 4900), predict [4900, 6791) without refitting
    tr, te = slice(921, 4900), slice(4900, 6791)
    w0, c0 = time.perf_counter(), time.process_time()
    f = I.identify(rb, I.Data(t[tr], q[tr], tau[tr], fit))
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    pred = I.predict(rb, f, t[te], q[te], fit)
    nominal = I.nominal_torques(rb, I.Data(t[te], q[te], tau[te], fit), fit)
    floor = tau[te][:, fit] - lowpass(tau[te][:, fit], sample_rate(t), 4.0)
    show("split: fitted on rows [921, 4900), predicting [4900, 6791), raw converted effort (N·m)",
         {"robocal": figures(pred - tau[te][:, fit]),
          **({"FIGAROH (run)": figaroh_figures(theirs["split"])} if "split" in theirs else
             {"FIGAROH (issue)": FIGAROH_SPLIT}),
          "URDF as drawn": figures(nominal - tau[te][:, fit]) | {},
          "effort > 4 Hz": figures(floor)})
    nominal_theirs = theirs["split"]["nominal_pooled"] if "split" in theirs else FIGAROH_NOMINAL_SPLIT
    if "split" in theirs:
        print(f"  FIGAROH's fit on [921, 4900): {theirs['split']['n_base']} base parameters, training RMSE "
              f"{theirs['split']['train_rmse']:.3f} N·m (its low-passed, decimated effort)")
    print(f"  FIGAROH's nominal pooled on the split: {nominal_theirs:.3f}; robocal's model: "
          f"{f.choice.label()}, {f.base.rank} base parameters; identify {wall:.2f} s wall, {cpu:.2f} s CPU")

    if args.quick:
        return

    # contiguous-block cross-validation over the excitation [921, 6791)
    w = slice(921, 6791)
    data = I.Data(t[w], q[w], tau[w], fit)
    g = I.identify(rb, data)
    cv = figures(g.cv_residuals)
    show("contiguous-block cross-validation on [921, 6791) (5 blocks, 0.5 s guard), raw converted effort (N·m)",
         {"robocal": cv, **({"FIGAROH (run)": figaroh_figures(theirs["cv"])} if "cv" in theirs else {"FIGAROH": {}})})
    if "cv" not in theirs:
        print("  FIGAROH's cross-validated figures: not run here (give --figaroh and --figaroh-examples)")
    # nested: each block predicted by a model whose choice and fit never saw it (its own inner blocks)
    nested = np.empty_like(g.cv_residuals)
    for held in blocks(len(data.t), 5):
        use = train_rows(len(data.t), held, int(round(0.5 * sample_rate(data.t))))
        h = I.identify(rb, data, rows=use)
        nested[held] = (I.predict(rb, h, data.t, data.q, fit) - data.tau[:, fit])[held]
    show("the same blocks, the choice nested (each block's model chosen and fitted on the other blocks only)",
         {"robocal (nested)": figures(nested),
          **({"FIGAROH (run)": figaroh_figures(theirs["cv"])} if "cv" in theirs else {})})

    if (DATA / "calibration_slow" / "tiago_effort.csv").is_file():
        ts, qs, taus, _ = load("calibration_slow", desc, rb)
        ps = I.predict(rb, g, ts, qs, fit)
        ns = I.nominal_torques(rb, I.Data(ts, qs, taus, fit), fit)
        show("validation run calibration_slow, fitted on [921, 6791), no refit (N·m)",
             {"robocal": figures(ps - taus[:, fit]), "FIGAROH (README)": FIGAROH_SLOW,
              "URDF (robocal)": figures(ns - taus[:, fit]), "URDF (FIGAROH)": FIGAROH_NOMINAL_SLOW})
    else:
        print("\nvalidation run calibration_slow: absent (listed in protocol.yaml, not shipped); FIGAROH's "
              "published 1.722 N·m pooled not compared")

    if not args.no_diagnosis:
        from pipeline.diagnose.adapters.dynamics_diagnosis import diagnose

        c0 = time.process_time()
        doc = diagnose(rb, data, g)
        print(f"\ndynamics diagnosis of [921, 6791) ({time.process_time() - c0:.1f} s CPU): {doc['status']} — "
              f"{doc['status_reason']}")
        print(f"  held-out (contiguous blocks) {doc['holdout_rms_before_m']:.3f} → {doc['holdout_rms_after_m']:.3f} N·m "
              "pooled; per joint " + ", ".join(f"{j} {a:.3f} → {b:.3f}" for j, a, b in zip(
                  doc["joints"], doc["holdout_rms_joint_before"], doc["holdout_rms_joint_after"])))
        for fd in doc["findings"]:
            pars = ", ".join(f"{p['name']} {p['value']:.4g} ± {p['std']:.2g} {p['unit']}" for p in fd["parameters"])
            print(f"  found {fd['effect']}@{fd['location']}: {pars} ({fd['confidence']})")
        for fd in doc["rejected_findings"]:
            print(f"  rejected {fd['effect']}@{fd['location']}: {fd['note']}")
        print("  not identifiable: " + "; ".join(f"{n['effect']}@{n['location']} ({n['reason']})"
                                                 for n in doc["not_identifiable"]))
        print("  drive scales: " + "; ".join(
            f"{d['joint']} " + (f"relative scale detectable from {d['min_detectable_relative']:.1%}" if d["identifiable"]
                                else "not identifiable") for d in doc["drive_scale"]["per_joint"]))

    if args.no_speed:
        return
    # speed: 8 000 samples × 8 fitted joints, filter + regressor + fit (one model), the held-out choice, the diagnosis
    n = 8000
    tt = np.arange(n) * 0.01
    qq = np.vstack([q, q[::-1]])[:n]
    yy = np.vstack([tau, tau[::-1]])[:n]
    every = np.ones(len(desc.joint_names), bool)
    d8 = I.Data(tt, qq, yy, every)
    w0, c0 = time.perf_counter(), time.process_time()
    I.identify(rb, d8, candidates=(I.Choice(cutoff_hz=4.0),), solvers=("ols",), folds=2)
    one = (time.perf_counter() - w0, time.process_time() - c0)
    w0, c0 = time.perf_counter(), time.process_time()
    g8 = I.identify(rb, d8)
    full = (time.perf_counter() - w0, time.process_time() - c0)
    w0, c0 = time.perf_counter(), time.process_time()
    if not args.no_diagnosis:
        from pipeline.diagnose.adapters.dynamics_diagnosis import diagnose

        diagnose(rb, d8, g8)
    diag = (time.perf_counter() - w0, time.process_time() - c0)
    print(f"\nspeed, {n} samples × {len(desc.joint_names)} fitted joints: filter + regressor + fit {one[0]:.2f} s wall "
          f"({one[1]:.2f} s CPU); with the held-out model choice ({len(I.DEFAULT_CANDIDATES)} structures × 5 blocks, "
          f"3 solvers) {full[0]:.2f} s wall ({full[1]:.2f} s CPU); diagnosis {diag[0]:.2f} s wall ({diag[1]:.2f} s CPU); "
          f"choice + diagnosis {full[0] + diag[0]:.2f} s wall ({full[1] + diag[1]:.2f} s CPU); target ≤ 30 s")


if __name__ == "__main__":
    main()
