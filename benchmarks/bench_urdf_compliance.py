"""Gravity compliance of a URDF robot (issue 18, `pipeline/diagnose/urdf_gravity.py`) on campaigns from
the independent generator of `tests/test_urdf_compliance.py` (own FK of the URDF text, torques as −∂V/∂q).

Per seed: a clean campaign (false findings) and one with joint `--joint` at `--mult` × its minimum
detectable size (read from the clean diagnosis' `candidates[].min_detectable`); found and named,
relative error of the compliance, held-out RMS after over the clean one.

Usage: ``python benchmarks/bench_urdf_compliance.py [--seeds 20] [--joint 1] [--mult 4]``
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import test_urdf_compliance as tc  # noqa: E402

from pipeline.diagnose.diagnose import Settings, diagnose  # noqa: E402
from pipeline.diagnose.urdf_robot import adapter  # noqa: E402

S = Settings(n_boot=10, sign_flips=0)


def run(comp: dict, seed: int) -> dict:
    model, table = tc.campaign(comp, seed)
    return diagnose(model, table, settings=S, adapter=adapter(model, table, held=()))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--joint", type=int, default=1)
    ap.add_argument("--mult", type=float, default=4.0)
    a = ap.parse_args()
    t0 = time.time()
    name = f"j{a.joint + 1}"
    false, found, err, ratio = [], [], [], []
    for seed in range(100, 100 + a.seeds):
        clean = run({}, seed)
        false.append(bool(clean["findings"]))
        mds = next(c["min_detectable"] for c in clean["candidates"]
                   if c["effect"] == "joint_compliance" and c["location"] == name)
        c = a.mult * mds
        d = run({a.joint: c}, seed)
        hit = [f for f in d["findings"] if (f["effect"], f["location"]) == ("joint_compliance", name)]
        found.append(bool(hit) and len(d["findings"]) == 1)
        if hit:
            err.append(abs(hit[0]["parameters"][0]["value"] / c - 1))
        ratio.append(d["holdout_rms_after_m"] / clean["holdout_rms_before_m"])
    out = {"joint": name, "mult": a.mult, "seeds": a.seeds, "clean_false_findings": float(np.mean(false)),
           "found_and_named_alone": float(np.mean(found)), "median_relative_error": float(np.median(err)),
           "after_over_clean_median": float(np.median(ratio)), "elapsed_s": round(time.time() - t0)}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
