"""The diagnosis' acceptance case: touch-jig campaign with 0.2 mm of joint-2 gravity compliance
(payload varied 0/6 kg), 0.05 mm noise (repeatability 3σ 0.15 mm), 100 contacts.

Two campaigns are compared on the same seeds:
- ``plain``: 100 random targets, payload alternating in blocks of 10 contacts (the default
  `Variations(payloads_kg=(0, 6))`);
- ``paired``: the integrator's plan for a payload campaign — 50 points chosen D-optimally
  (geometry + gravity compliance of every loaded joint, nominal model, `effects.compliance_design`)
  out of 150 IK'd candidates, each touched once per payload (`payload_pairs=True`).

Per campaign: found and correctly named rate, held-out RMS after modelling / the clean
floor (same seed, no effect), median relative parameter error, 95 % CI coverage, the
minimum detectable compliance.  Usage:
``python benchmarks/bench_diagnose_acceptance.py [--seeds 30] [--campaigns 3,11] [--only paired]``.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from pipeline.diagnose import Settings, diagnose
from pipeline.models.jig import stepped_block
from pipeline.simulate import effects as se
from pipeline.simulate.arc_welder import Campaign, Noise
from pipeline.systems import arc_welder as aw

NOM, TRUE, JIG = aw.nominal_arm(), aw.reference_truth(), stepped_block()
NOISE = Noise(repeatability_3sigma_m=1.5e-4)
PAYLOADS = (0.0, 6.0)
C_TRUE = 3.56e-6  # rad/(N·m): 0.2 mm RMS tip deflection over this campaign
KEY = ("joint_compliance", "J2")


GEOMETRY_WEIGHT = 0.0


def campaign(kind: str, seed: int):
    """(campaign, targets, variations) of the plain or the payload-paired campaign."""
    c = Campaign(contacts=100, seed=seed)
    if kind == "paired":
        return c, se.plan_targets(NOM, JIG, c, truth=TRUE, payloads_kg=PAYLOADS,
                                 geometry_weight=GEOMETRY_WEIGHT), \
            se.Variations(payloads_kg=PAYLOADS, payload_pairs=True)
    return c, se.plan_targets(NOM, JIG, c, truth=TRUE), se.Variations(payloads_kg=PAYLOADS)


def diag(c, targets, var, effects, seed):
    es = se.run(NOM, TRUE, JIG, targets, c, NOISE, effects, var, seed=seed)
    return diagnose(aw.TouchModel(NOM), se.diagnosis_table(es, JIG), jig_tolerance_m=JIG.tolerance_m,
                    settings=Settings(n_boot=0))


def measure(kind: str, cseed: int, seeds: int) -> dict:
    c, targets, var = campaign(kind, cseed)
    found, ratio, rel, cover, mds, floors = 0, [], [], [], [], []
    for s in range(seeds):
        floor = diag(c, targets, var, [], s)["holdout_rms_before_m"]
        floors.append(floor)
        d = diag(c, targets, var, [se.Injected("joint_compliance", (C_TRUE,), "J2")], s)
        ratio.append(d["holdout_rms_after_m"] / floor)
        mds.append(next(g["min_detectable"] for g in d["candidates"] if (g["effect"], g["location"]) == KEY))
        f = [f for f in d["findings"] if (f["effect"], f["location"]) == KEY]
        if f:
            found += 1
            p = f[0]["parameters"][0]
            rel.append(abs(p["value"] - C_TRUE) / C_TRUE)
            cover.append(p["ci95"][0] <= C_TRUE <= p["ci95"][1])  # the reported (t-based) 95 % interval
    ratio = np.array(ratio)
    return {"campaign": kind, "campaign_seed": cseed, "seeds": seeds, "found_named": found / seeds,
            "holdout_after_over_floor_median": float(np.median(ratio)), "holdout_after_over_floor_max": float(ratio.max()),
            "share_within_1.2_floor": float(np.mean(ratio <= 1.2)),
            "median_rel_error": float(np.median(rel)) if rel else None,
            "ci95_coverage": float(np.mean(cover)) if cover else None,
            "mds_rad_per_Nm": float(np.median(mds)), "true_rad_per_Nm": C_TRUE,
            "clean_floor_m_median": float(np.median(floors))}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=30)
    ap.add_argument("--campaigns", default="3,11")
    ap.add_argument("--only", default="", help="plain or paired (default: both)")
    ap.add_argument("--geometry-weight", type=float, default=0.0,
                    help="paired campaign: blend of D-optimality into the Ds design (effects.compliance_design)")
    a = ap.parse_args()
    global GEOMETRY_WEIGHT
    GEOMETRY_WEIGHT = a.geometry_weight
    t0 = time.time()
    kinds = [a.only] if a.only else ["plain", "paired"]
    rows = []
    for cs in (int(v) for v in a.campaigns.split(",")):
        for kind in kinds:
            rows.append(measure(kind, cs, a.seeds))
            print(json.dumps(rows[-1]), flush=True)
    print(f"elapsed {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
