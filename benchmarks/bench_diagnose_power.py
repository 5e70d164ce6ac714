"""Power of the diagnosis on campaigns it did not make (`tests/independent_touch.py`), seeds × effects.

Each effect is injected at `--mult` × its minimum detectable size (3σ over the norm of its signature ⊥ the
geometric Jacobian, computed by the generator itself) into 100-contact touch campaigns of one plan:
`--plan robocal` (default) robocal's own campaign — `robocal plan arc-welder --select 115` written to a plan
file, which the generator reads as plain JSON (`tests/independent_campaign_file.py`), its first 100 contacts
that touch on the true arm; `--plan generator` the generator's own random one (random face points, random
order: `independent_touch.plan`).

- in library: backlash of J1, J2, J3 (the load lags the motor by half the play, the sign of the joint's
  velocity along the search), joint compliance of J2 in a single-payload campaign (6 kg throughout: the
  gravity torque's shape over the poses is all that tells it from a J2→J3 coupling), thermal growth (every
  link's a, d grow linearly in time);
- out of library: a Gaussian bump in J2's transmission, a dent in one face.

Per case: `named` (the right effect at the right place among the findings; thermal: the family
thermal_growth@links, any form), `named_high` (and with high confidence), `located` (out of library: status
partially_explained / unexplained, or a place named in `unexplained_where`), `misnamed_high` (a high-confidence finding that is not the injected
effect), `worse` (the final model's held-out RMS above geometry alone's), and the gate's own minimum
detectable size on that campaign (Bonferroni over the library and 80 % power: stricter than the
generator's 3σ), and for backlash the generator's figure at the injected size without the one contact that carries most
of the signature (`mds_generator_without_top_contact`: a finding resting on one record is not reported).
Targets: named ≥ 95 % in library, located ≥ 80 % out of library, misnamed with high confidence ≤ 10 %,
worse 0.

Backlash at J2 on the generator's random plan is below that target by the campaign, not by the diagnosis:
J2 turns the same way during the search on almost every face, so the geometry (J2's offset) absorbs the
signature but on a few contacts, and one contact carries a third of the rest.  That contact is >9σ off the
geometric fit and set aside; without it the detectable play is 2.5× larger (1.33 vs 0.53 mrad at the injected
2.1 mrad).  Keeping the contact only moves the finding to "rests on one record" (not reported).  The remedy is
the campaign's: approach J2 both ways.  robocal's plan does (`approach_balance` in the campaign file: its
constant-orientation searches turn J2 both ways on many faces), J2's detectable play there is 0.12 mrad and
leaving out its top contact raises it 1.25×, not 2.5×.

The dent sits where the campaign samples a face (`dent_place`): top2 at (0.15, 0.1) m as before where the
campaign touches within its radius of there (the random plan), else the median point of the face the campaign
touches most (robocal's plan has 5 contacts on top2, none within 59 mm of that point: a dent under one or two
contacts is refused by design, as the backlash above).

Usage: ``python benchmarks/bench_diagnose_power.py [--seeds 20] [--mult 4] [--cases a,b] [--out f.json]``.
(CI runs a bounded version: tests/test_diagnose_power.py.)
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import independent_campaign_file as icf  # noqa: E402
import independent_touch as it  # noqa: E402
from touch_ingest import diagnosis_table  # noqa: E402

from pipeline.diagnose import Settings, diagnose  # noqa: E402
from pipeline.systems import arc_welder as aw  # noqa: E402

REPEATABILITY = 1e-4


def cases(targets: it.Targets) -> dict[str, tuple[it.Effect, dict, tuple | None]]:
    """name → (the generator's effect at unit size, campaign options, (effect, location prefix) when in library)."""
    q2 = float(np.median(targets.q_a[:100, 1]))
    dent_face, dent = dent_place(targets)
    return {
        "backlash_J1": (it.Effect("backlash", 1.0, {"joint": 0}), {}, ("backlash", "J1")),
        "backlash_J2": (it.Effect("backlash", 1.0, {"joint": 1}), {}, ("backlash", "J2")),
        "backlash_J3": (it.Effect("backlash", 1.0, {"joint": 2}), {}, ("backlash", "J3")),
        "compliance_J2_single_payload": (it.Effect("compliance", 1.0, {"joint": 1}), {"payload_kg": 6.0},
                                         ("joint_compliance", "J2")),
        "thermal": (it.Effect("linear_growth", 1.0), {}, ("thermal_growth", "links")),
        "bump": (it.Effect("bump", 1.0, {"joint": 1, "centre": q2, "width": 0.1}), {}, None),
        "dent": (it.Effect("dent", 1.0, {"face": dent_face, "centre": dent, "radius": DENT_RADIUS}), {}, None),
    }


DENT_FACE, DENT_AT, DENT_RADIUS = 1, (0.15, 0.1), 0.03  # the dent: face top2 at (x, y), its radius, m


def dent_place(targets: it.Targets) -> tuple[int, tuple[float, float]]:
    """(face, centre) of the dent: top2 at `DENT_AT` when the campaign touches it within one radius of there,
    else the median point of the face the campaign touches most (a dent where no contact or a single one
    looks is not one any diagnosis can locate — a structure resting on one or two records is refused by
    design; the bump is likewise at the campaign's median J2).  The points: the approach poses' tips (nominal
    arm), whose search runs along the face normal, on the face's two other axes."""
    nom, _ = it.default_arms()
    faces = it.stepped_block().faces
    face = targets.face[:100]

    def points(f):
        return it.tip(nom, targets.q_a[:100][face == f])[:, list(faces[f].other_axes())]

    near = points(DENT_FACE)
    if near.size and np.min(np.linalg.norm(near - np.array(DENT_AT), axis=1)) <= DENT_RADIUS:
        return DENT_FACE, DENT_AT
    f = int(np.argmax(np.bincount(face, minlength=len(faces))))
    return f, tuple(float(v) for v in np.median(points(f), axis=0))


def score(d: dict, key: tuple | None) -> dict:
    """One diagnosis against the injected effect (module docstring)."""
    def right(f):
        return key is not None and f["effect"] == key[0] and f["location"].split(" (")[0] == key[1]
    named = any(right(f) for f in d["findings"])
    return {"status": d["status"], "named": named,
            "named_high": any(right(f) and f["confidence"] == "high" for f in d["findings"]),
            # out of library: a status that says something is left, or a located place (unexplained_where)
            "located": d["status"] in ("partially_explained", "unexplained") or bool(d["unexplained_where"]),
            "misnamed_high": any(f["confidence"] == "high" and not right(f) for f in d["findings"]),
            "worse": d["holdout_rms_after_m"] > d["holdout_rms_before_m"] + 1e-15,
            "findings": [f"{f['effect']}@{f['location']}:{f['confidence']}" for f in d["findings"]],
            "where": [w["variable"] for w in d["unexplained_where"]][:3]}


def gate_mds(d: dict, key: tuple | None) -> float | None:
    """The gate's minimum detectable size of the injected library effect on this campaign."""
    for c in d["candidates"] if key else ():
        if (c["effect"], c["location"]) == key:
            return c["min_detectable"]
    return None


def run_case(world, name: str, mult: float, seeds, n_boot: int) -> dict:
    nom, tru, targets, sigma = world
    form, campaign, key = cases(targets)[name]
    mds = it.mds(nom, tru, targets, form, sigma, **campaign)
    eff = it.Effect(form.kind, mult * mds, form.where)
    rows, gm = [], None
    for s in seeds:
        c = it.run(nom, tru, targets, (eff,), seed=s, **campaign)
        d = diagnose(aw.TouchModel(aw.nominal_arm()), diagnosis_table(c),
                     settings=Settings(n_boot=n_boot, repeatability_3sigma_m=REPEATABILITY))
        rows.append({"seed": s, **score(d, key)})
        gm = gm if gm is not None else gate_mds(d, key)
    rate = lambda k: float(np.mean([r[k] for r in rows]))  # noqa: E731
    # the same figure at the injected size with the one contact that carries most of the signature left out:
    # a finding resting on one record is not reported (`verdict.outliers`), so this is the size the diagnosis
    # can show robustly (J2 backlash in this plan: J2 reverses before the search at few contacts)
    robust = (it.mds(nom, tru, targets, eff, sigma, at_size=True, drop_top=1, **campaign)
              if key and key[0] == "backlash" else None)
    out = {"mds_generator": mds, "size": mult * mds, "mds_gate": gm, "runs": len(rows),
           "mds_generator_without_top_contact": robust,
           "in_library": key is not None, "misnamed_high": rate("misnamed_high"), "worse": int(sum(r["worse"] for r in rows)),
           "statuses": {k: int(sum(r["status"] == k for r in rows)) for k in sorted({r["status"] for r in rows})}}
    out.update({"named": rate("named"), "named_high": rate("named_high")} if key else {"located": rate("located")})
    out["per_seed"] = rows
    return out


def planned_targets(nom, tru, m: int = 100, select: int = 115, seed: int = 0, backlash: bool = False,
                    candidates: int = 1000) -> it.Targets:
    """robocal's own campaign (`robocal plan arc-welder --candidates CANDIDATES --select SELECT`), written to a plan file and read back
    by the generator as plain JSON (`independent_campaign_file.from_campaign`): its first m contacts whose search
    touches on the true arm (`independent_campaign_file.touching`), in the plan's order."""
    import tempfile

    from pipeline.plan.arc_welder import touch_campaign
    from pipeline.plan.campaign import write_document

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "campaign.json"
        write_document(path, touch_campaign(candidates, select, seed, backlash=backlash))
        targets = icf.from_campaign(json.loads(path.read_text()))
    ok = np.flatnonzero(icf.touching(nom, tru, targets))
    if ok.size < m:
        raise RuntimeError(f"robocal's plan: only {ok.size} of {select} contacts touch on the true arm")
    return icf.take(targets, ok[:m])


def world(plan: str = "robocal", m: int = 120, candidates: int = 1000):
    """(nominal, truth, targets, σ along the normal): the campaign robocal plans (`plan` "robocal"; "robocal-backlash":
    planned for every joint's backlash too, `robocal plan --backlash`), or the
    generator's own random one (`plan` "generator": m approach poses on random face points, random order)."""
    nom, tru = it.default_arms()
    targets = (planned_targets(nom, tru, backlash=plan == "robocal-backlash", candidates=candidates)
               if plan.startswith("robocal")
               else it.plan(nom, it.stepped_block(), m=m, seed=1))
    return nom, tru, targets, it.run(nom, tru, targets, (), seed=0).along_normal_noise_sigma_m


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=100)
    ap.add_argument("--mult", type=float, default=4.0)
    ap.add_argument("--cases", default="")
    ap.add_argument("--n-boot", type=int, default=20)
    ap.add_argument("--out", default="")
    ap.add_argument("--plan", default="robocal", choices=("robocal", "robocal-backlash", "generator", "random"),
                    help="the campaign: robocal's plan (robocal plan arc-welder [--backlash]), the generator's random one "
                         "(searches along the face normals), or (random) a new random campaign per seed with random "
                         "search directions and speeds, mixed payloads and a servo's encoder stream "
                         "(benchmarks/power_random.py)")
    ap.add_argument("--mults", default="4,2", help="--plan random: the multiples of the ideal MDE injected")
    ap.add_argument("--no-budget", action="store_true", help="--plan random: skip the power budget per term")
    ap.add_argument("--stream-noise", type=float, default=1.0,
                    help="--plan random: the logged encoder stream's reading noise, counts (the latches have none)")
    ap.add_argument("--clean-only", action="store_true", help="--plan random: only the clean campaigns (false findings)")
    ap.add_argument("--budget-only", action="store_true",
                    help="--plan random: only the power budget per term (robocal's detectable size beside the ideal's)")
    ap.add_argument("--table", default="", help="print the tables of a saved `--plan random --out` file and stop")
    a = ap.parse_args()
    t0 = time.time()
    if a.table:
        import power_random as pr

        print(pr.markdown(json.loads(Path(a.table).read_text())["summary"]))
        return
    if a.plan == "random":
        import power_random as pr

        rows: list = []
        summary = pr.report(range(a.first_seed, a.first_seed + a.seeds), tuple(float(v) for v in a.mults.split(",")),
                            a.cases.split(",") if a.cases else None, a.n_boot, budgets=not a.no_budget, out=rows,
                            stream_noise_counts=a.stream_noise, clean_only=a.clean_only,
                            budget_only=a.budget_only, save=a.out and a.out + ".partial")
        print(pr.markdown(summary))
        print(f"elapsed {time.time() - t0:.0f} s")
        if a.out:  # the summary and every seed's row
            per = {f"{k[0]} {k[1]}": v for k, v in rows[0].items()}
            Path(a.out).write_text(json.dumps({"summary": summary, "rows": per}, indent=1, default=float))
        return
    w = world(a.plan)
    names = a.cases.split(",") if a.cases else list(cases(w[2]))
    seeds = range(a.first_seed, a.first_seed + a.seeds)
    report = {"seeds": a.seeds, "mult": a.mult, "plan": a.plan}
    for name in names:
        r = run_case(w, name, a.mult, seeds, a.n_boot)
        report[name] = r
        print(json.dumps({name: {k: v for k, v in r.items() if k != "per_seed"}}), flush=True)
    inlib = [report[n] for n in names if report[n]["in_library"]]
    outlib = [report[n] for n in names if not report[n]["in_library"]]
    report["summary"] = {
        "named_min_in_library": min((r["named"] for r in inlib), default=None),
        "located_min_out_of_library": min((r["located"] for r in outlib), default=None),
        "misnamed_high_max": max(r["misnamed_high"] for r in inlib + outlib),
        "worse_total": int(sum(r["worse"] for r in inlib + outlib)),
        "targets": {"named": 0.95, "located": 0.80, "misnamed_high": 0.10, "worse": 0}}
    report["elapsed_s"] = time.time() - t0
    print(json.dumps({"summary": report["summary"]}))
    print(f"elapsed {report['elapsed_s']:.0f} s")
    if a.out:
        Path(a.out).write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
