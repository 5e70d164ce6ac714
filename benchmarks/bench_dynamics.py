"""Dynamics identification on FIGAROH's TIAGo protocol, side by side: robocal vs FIGAROH vs the URDF as
drawn, per scored joint and pooled (N·m), on the frozen split and by contiguous-block cross-validation;
and the speed of filter + regressor + fit on 8 000 samples × 8 joints.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_dynamics.py
    PYTHONPATH=. .venv/bin/python benchmarks/bench_dynamics.py --figaroh-json FIGAROH.json   # a FIGAROH run's figures

Data: ../shared/real-data/figaroh_tiago_dynamics (training run `dynamic/`; the validation run
`calibration_slow/` where present).  Efforts are converted exactly as FIGAROH does (reduction ratio × kmotor,
the differential wrist τ6 = k(e7 − e6), τ7 = k(e6 + e7), the torso's 9.81 × subtree mass); arm_1–4 are fitted
and scored.  FIGAROH's figures: the split's as FIGAROH 1.0.2 gave them when fitted on [921, 4900) and
predicting [4900, 6791) without refitting, on the raw converted effort at the recorded rate (the issue's
reproduction), and its published held-out figure on `calibration_slow` (its README).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from pipeline.dynamics import effort as E
from pipeline.dynamics import identify as I
from pipeline.dynamics import rigid_body as RB
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--figaroh-json", type=Path, help="figures of a FIGAROH run: {split: {joint: RMS, pooled: …}, "
                    "cv: {…}}")
    args = ap.parse_args()
    if not (DATA / "dynamic" / "tiago_effort.csv").is_file():
        print(f"{DATA} is absent: nothing to compare")
        return
    desc = U.read(DATA / "tiago_48_hey5.urdf", "base_footprint", "arm_7_link")
    rb = RB.build(desc.urdf, desc.joint_names)
    t, q, tau, fit = load("dynamic", desc, rb)
    theirs = json.loads(args.figaroh_json.read_text()) if args.figaroh_json else {}

    # the frozen split: fit [921, 4900), predict [4900, 6791) without refitting
    tr, te = slice(921, 4900), slice(4900, 6791)
    w0, c0 = time.perf_counter(), time.process_time()
    f = I.identify(rb, I.Data(t[tr], q[tr], tau[tr], fit))
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    pred = I.predict(rb, f, t[te], q[te], fit)
    nominal = I.nominal_torques(rb, I.Data(t[te], q[te], tau[te], fit), fit)
    floor = tau[te][:, fit] - lowpass(tau[te][:, fit], sample_rate(t), 4.0)
    show("split: fitted on rows [921, 4900), predicting [4900, 6791), raw converted effort (N·m)",
         {"robocal": figures(pred - tau[te][:, fit]), "FIGAROH (issue)": FIGAROH_SPLIT,
          **({"FIGAROH (run)": theirs["split"]} if "split" in theirs else {}),
          "URDF as drawn": figures(nominal - tau[te][:, fit]) | {},
          "effort > 4 Hz": figures(floor)})
    print(f"  FIGAROH's nominal pooled on the split: {FIGAROH_NOMINAL_SPLIT:.3f}; robocal's model: "
          f"{f.choice.label()}, {f.base.rank} base parameters; identify {wall:.2f} s wall, {cpu:.2f} s CPU")

    # contiguous-block cross-validation over the excitation [921, 6791)
    w = slice(921, 6791)
    g = I.identify(rb, I.Data(t[w], q[w], tau[w], fit))
    cv = figures(g.cv_residuals)
    show("contiguous-block cross-validation on [921, 6791) (5 blocks, 0.5 s guard), raw converted effort (N·m)",
         {"robocal": cv, **({"FIGAROH (run)": theirs["cv"]} if "cv" in theirs else {"FIGAROH": {}})})
    if "cv" not in theirs:
        print("  FIGAROH's cross-validated figures: not run here (give --figaroh-json)")

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

    # speed: 8 000 samples × 8 joints, filter + regressor + fit (one model), then the whole held-out choice
    n = 8000
    tt = np.arange(n) * 0.01
    qq = np.vstack([q, q[::-1]])[:n]
    yy = np.vstack([tau, tau[::-1]])[:n]
    w0, c0 = time.perf_counter(), time.process_time()
    I.identify(rb, I.Data(tt, qq, yy, fit), candidates=(I.Choice(cutoff_hz=4.0),), solvers=("ols",), folds=2)
    one = (time.perf_counter() - w0, time.process_time() - c0)
    w0, c0 = time.perf_counter(), time.process_time()
    I.identify(rb, I.Data(tt, qq, yy, fit))
    full = (time.perf_counter() - w0, time.process_time() - c0)
    print(f"\nspeed, {n} samples × {len(desc.joint_names)} joints: filter + regressor + fit {one[0]:.2f} s wall "
          f"({one[1]:.2f} s CPU); with the held-out model choice (6 structures × 5 blocks, 3 solvers) "
          f"{full[0]:.2f} s wall ({full[1]:.2f} s CPU); target ≤ 30 s")


if __name__ == "__main__":
    main()
