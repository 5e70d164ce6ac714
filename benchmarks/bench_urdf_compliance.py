"""Gravity compliance of a URDF robot (the diagnosis' gravity-compliance term) on campaigns from
the independent generator `tests/independent_drive.py` (own FK of the URDF text, torques as −∂V/∂q), through
`tests/test_urdf_compliance.py`'s `campaign`.

Per seed: a clean campaign (false findings) and one with joint `--joint` at `--mult` × its minimum
detectable size (read from the clean diagnosis' `candidates[].min_detectable`); found and named,
relative error of the compliance, held-out RMS after over the clean one.

With ``--source torque``: campaigns of `tests/independent_drive.py` (the same robot carrying a
`--payload-kg` payload its URDF does not describe, drives logging their efforts, written as recordings
and read back); compliance from the measured torques, and for comparison the URDF inertial model on
the same measurements (efforts dropped): how often it names the joint alone within 20 % of the truth.

Usage: ``python benchmarks/bench_urdf_compliance.py [--seeds 20] [--joint 1] [--mult 4] [--source inertial|torque]
[--payload-kg 10]``
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import test_urdf_compliance as tc  # noqa: E402

from pipeline.diagnose import Settings, diagnose  # noqa: E402
from pipeline.diagnose.adapters.urdf_robot import adapter  # noqa: E402

S = Settings(n_boot=10, sign_flips=0)


def run(comp: dict, seed: int, source: str = "inertial", payload_kg: float = 0.0, inertial: bool = False) -> dict:
    """Diagnosis of one campaign; `inertial` (torque source): drop the efforts, the URDF model's view."""
    if source == "inertial":
        model, table = tc.campaign(comp, seed)
    else:
        import test_drive_state as td

        (j, c), = comp.items() if comp else ((1, 0.0),)
        assert j == 1, "the torque campaigns make j2 compliant"
        with tempfile.TemporaryDirectory() as d:
            model, table = td.recording(Path(d) / "r.mcap", seed, c, payload_kg)
        if inertial:
            table = {k: v for k, v in table.items() if k not in ("joint_efforts", "commanded_positions")}
    return diagnose(model, table, settings=S, adapter=adapter(model, table, held=()))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--joint", type=int, default=1)
    ap.add_argument("--mult", type=float, default=4.0)
    ap.add_argument("--source", choices=("inertial", "torque"), default="inertial")
    ap.add_argument("--payload-kg", type=float, default=10.0)
    a = ap.parse_args()
    kw = {"source": a.source, "payload_kg": a.payload_kg}
    t0 = time.time()
    name = f"j{a.joint + 1}"
    false, found, err, ratio, urdf_ok = [], [], [], [], []
    for seed in range(100, 100 + a.seeds):
        clean = run({}, seed, **kw)
        false.append(bool(clean["findings"]))
        mds = next(c["min_detectable"] for c in clean["candidates"]
                   if c["effect"] == "joint_compliance" and c["location"] == name)
        c = a.mult * mds
        d = run({a.joint: c}, seed, **kw)
        hit = [f for f in d["findings"] if (f["effect"], f["location"]) == ("joint_compliance", name)]
        if a.source == "torque":
            hit = [f for f in hit if f.get("source") == "measured torque"]
            u = run({a.joint: c}, seed, **kw, inertial=True)
            uh = [f for f in u["findings"] if (f["effect"], f["location"]) == ("joint_compliance", name)]
            urdf_ok.append(len(u["findings"]) == 1 and bool(uh) and abs(uh[0]["parameters"][0]["value"] / c - 1) < 0.2)
        found.append(bool(hit) and len(d["findings"]) == 1)
        if hit:
            err.append(abs(hit[0]["parameters"][0]["value"] / c - 1))
        ratio.append(d["holdout_rms_after_m"] / clean["holdout_rms_before_m"])
    out = {"joint": name, "mult": a.mult, "seeds": a.seeds, "source": a.source,
           **({"payload_kg": a.payload_kg, "urdf_model_named_alone_within_20pct": float(np.mean(urdf_ok))}
              if a.source == "torque" else {}),
           "clean_false_findings": float(np.mean(false)),
           "found_and_named_alone": float(np.mean(found)), "median_relative_error": float(np.median(err)),
           "after_over_clean_median": float(np.median(ratio)), "after_over_clean_max": float(np.max(ratio)),
           "after_within_1.2x_clean": float(np.mean(np.array(ratio) <= 1.2)), "elapsed_s": round(time.time() - t0)}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
