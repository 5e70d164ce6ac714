"""The diagnosis's power on the independent generator's random campaigns (`tests/independent_search.py`: random
search directions and speeds, mixed payloads, a servo's encoder stream with 1 count of reading noise by default),
against the ideal test — a helper of `bench_diagnose_power.py --plan random`.

Per seed a new campaign (its own plan and noise).  Per case the effect is injected at `mult` × the ideal test's
minimum detectable size on that campaign: the effect's true signature (the generator's, noise-free) projected off
the geometric Jacobian, known, t = 3: MDE = 3σ / ‖P⊥S‖ (backlash: the secant at the injected play, a fixed point,
since a dead band's shape changes with its play).  Per case and seed:

- `named` / `named_high` / `misnamed_high` (in library), `located` (out of library: a finding or an
  `unexplained_where` entry at the right joint or face);
- `named_or_near_collinear`: named, or listed beside a finding of lower than high confidence whose name the
  generator's own forms show spans ≥ 90 % of the true signature off the geometry on that campaign;
  `named_or_collinear_alike`: that, or listed beside such a finding whose swap for the true name the data cannot
  reject at the diagnosis's level at the injected size (`collinear_alike`: robocal's two look-alike measures,
  computed from the truth; both names with lowered confidence is the right answer there); `named_or_alike`
  counts any such listing, unchecked;
- the power budget on the clean campaign of the same plan (`budget`): the ideal MDE at 80 % power
  ((3 + z₀.₈)σ/‖P⊥S‖, like for like with robocal's figure), robocal's own `min_detectable` (its gate: its signature,
  its σ, Holm's family), and robocal's *effective* MDE for the true effect — (z_{1−α/2m} + z₀.₈)·σ̂ over the part of
  the true signature ⊥ robocal's geometry that robocal's candidate captures — split into its factors:
  multiplicity, σ̂/σ, geometry, signature capture; and in the ideal's own convention (50 % power) robocal's
  `detection_threshold` (its critical value × σ̂ over its signature ⊥) against the ideal's t = 3 figure; for the
  eccentricity (two parameters, its phase unknown to robocal) the same like for like at one phase at a time
  (`phase_budget`: the injected phase and robocal's weakest).
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import scipy.optimize
import scipy.stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import independent_search as isr  # noqa: E402
import independent_touch as it  # noqa: E402
from touch_ingest import diagnosis_table  # noqa: E402

from pipeline.diagnose import Settings, diagnose  # noqa: E402
from pipeline.systems import arc_welder as aw  # noqa: E402

REPEATABILITY = 1e-4
Z80 = float(scipy.stats.norm.ppf(0.8))

# name → (generator effects at unit size, the plan's payload (None: mixed), tangent unit, library key or None)
CASES = {
    "backlash_J1": ((("backlash", {"joint": 0}),), None, None, ("backlash", "J1")),
    "backlash_J2": ((("backlash", {"joint": 1}),), None, None, ("backlash", "J2")),
    "backlash_J3": ((("backlash", {"joint": 2}),), None, None, ("backlash", "J3")),
    "compliance_J2": ((("compliance", {"joint": 1}),), None, 1e-6, ("joint_compliance", "J2")),
    "compliance_J3": ((("compliance", {"joint": 2}),), None, 1e-6, ("joint_compliance", "J3")),
    "compliance_J2_single_payload": ((("compliance", {"joint": 1}),), 6.0, 1e-6, ("joint_compliance", "J2")),
    "eccentricity_J2": ((("eccentricity", {"joint": 1, "phase": 0.7}),), None, 1e-4, ("encoder_eccentricity", "J2")),
    "eccentricity_J3": ((("eccentricity", {"joint": 2, "phase": 2.0}),), None, 1e-4, ("encoder_eccentricity", "J3")),
    "scale_J2": ((("scale", {"joint": 1}),), None, 1e-4, ("joint_scale", "J2")),
    "wrist_coupling_J4_J5": ((("coupling", {"pair": (3, 4)}),), None, 1e-4, ("wrist_coupling", "J4->J5")),
    "coupling_J2_J3": ((("coupling", {"pair": (1, 2)}),), None, 1e-4, ("joint_coupling", "J2->J3")),
    "latency": ((("latency", {}),), None, 1e-3, ("trigger_latency", None)),
    "thermal_growth": ((("linear_growth", {}),), None, 1e-8, ("thermal_growth", "links")),
    "bump_J2": ((("bump", {"joint": 1, "width": 0.1}),), None, 1e-4, None),
    "dent": ((("dent", {"radius": 0.03}),), None, 1e-4, None),
    "compliance_J2+backlash_J3": ((("compliance", {"joint": 1}), ("backlash", {"joint": 2})), None, None,
                                  ("joint_compliance", "J2")),
}
SECOND = {"compliance_J2+backlash_J3": ("backlash", "J3")}  # the second effect of a pair case


class World:
    """One seed's campaign: the true arm's plan, its clean run (σ, the geometric Jacobian) and caches."""

    def __init__(self, seed: int, m: int = 120, stream_noise_counts: float = 1.0):
        self.seed = seed
        self.stream_noise = stream_noise_counts  # the logged stream's reading noise (counts; the latches have none)
        self.nom, self.tru = it.default_arms()
        self.sc = isr.plan(self.tru, m=m, seed=seed)
        self._c0: dict = {}

    def plan(self, payload_kg: float | None) -> isr.Searches:
        if payload_kg is None:
            return self.sc
        return replace(self.sc, payload=np.full(self.sc.face.size, float(payload_kg)))

    def clean(self, payload_kg: float | None):
        """(noise-free campaign, geometric Jacobian along each measured axis) of the plan."""
        if payload_kg not in self._c0:
            c0 = isr.run(self.nom, self.tru, self.plan(payload_kg), (), noise=0.0)
            ax = c0.contacts["axis"]
            self._c0[payload_kg] = (c0, it.geometric_jacobian(self.tru, c0.truth_joint_q, ax))
        return self._c0[payload_kg]


SIGMA = float(np.hypot(REPEATABILITY / 3, 2e-5 / np.sqrt(3)))  # the generator's noise along the normal


def placed(w: World, kind: str, where: dict) -> dict:
    """`where` completed with what depends on the campaign: the bump at the campaign's median J2, the dent at the
    median point of the face the campaign touches most."""
    where = dict(where)
    sc = w.sc
    if kind == "bump":
        where["centre"] = float(np.median(sc.q_a[:100, 1]))
    if kind == "dent":
        faces = it.stepped_block().faces
        f = int(np.argmax(np.bincount(sc.face[:100], minlength=len(faces))))
        pts = it.tip(w.tru, sc.q_a[:100][sc.face[:100] == f] + 0.0)[:, list(faces[f].other_axes())]
        where.update(face=f, centre=tuple(float(v) for v in np.median(pts, axis=0)))
    return where


def true_signature(w: World, kind: str, where: dict, size: float, payload_kg, secant: bool) -> np.ndarray:
    """(n,) m per unit: the residual change of one effect on this campaign (tangent at `size` or, `secant`, the
    secant at it), noise-free."""
    c0, _ = w.clean(payload_kg)
    c1 = isr.run(w.nom, w.tru, w.plan(payload_kg), (it.Effect(kind, size, where),), noise=0.0)
    ax = c0.contacts["axis"]
    rows = np.arange(ax.size)
    return (it.tip(w.tru, c1.truth_joint_q)[rows, ax] - it.tip(w.tru, c0.truth_joint_q)[rows, ax]) / size


def _perp(S: np.ndarray, J: np.ndarray) -> np.ndarray:
    U, sv, _ = np.linalg.svd(J, full_matrices=False)
    U = U[:, sv > sv[0] * 1e-9]
    return S - U @ (U.T @ S)


def ideal_mds(w: World, kind: str, where: dict, payload_kg, unit: float | None, mult: float) -> tuple[float, np.ndarray]:
    """(ideal MDE at t = 3, the true signature there).  `unit` None: a dead band — the secant at mult × MDE,
    iterated to a fixed point from a small play."""
    _, J = w.clean(payload_kg)
    if unit is not None:
        S = true_signature(w, kind, where, unit, payload_kg, False)
        return 3 * SIGMA / np.linalg.norm(_perp(S, J)), S
    size = 2e-4
    for _ in range(4):
        S = true_signature(w, kind, where, size, payload_kg, True)
        m = 3 * SIGMA / np.linalg.norm(_perp(S, J))
        if abs(mult * m - size) < 0.02 * size:
            break
        size = mult * m
    return m, S


def right(f: dict, key) -> bool:
    return (key is not None and f["effect"] == key[0]
            and (key[1] is None or f["location"].split(" (")[0] == key[1]))


def located_right(d: dict, kind: str, where: dict) -> bool:
    """An out-of-library effect located: a finding at its joint / face, or an unexplained_where entry there."""
    tag = f"J{where['joint'] + 1}" if kind == "bump" else it.stepped_block().faces[where["face"]].id
    hit = [f for f in d["findings"] if tag in f["location"]]
    near = [u for u in d["unexplained_where"] if tag in u["variable"]]
    return bool(hit or near)


# robocal's names → the generator's own forms spanning them (kind, where, tangent unit): the look-alike's signature
# on the campaign, computed by the generator, to tell whether it is near-collinear with the true effect there
def _forms_of(effect: str, location: str) -> list | None:
    base, quad = location.split(" (")[0], "(quadratic)" in location
    j = int(base[1]) - 1 if base[:1] == "J" and base[1:2].isdigit() else None
    if effect in ("encoder_eccentricity", "transmission_error"):
        kind = "eccentricity" if effect == "encoder_eccentricity" else "transmission"
        return [(kind, {"joint": j, "phase": ph}, 1e-4) for ph in (0.0, np.pi / 2)]
    if effect == "joint_scale":
        return [("scale", {"joint": j}, 1e-4)]
    if effect == "joint_compliance":
        return [("compliance", {"joint": j}, 1e-6)]
    if effect == "trigger_latency":
        return [("latency", {}, 1e-3)]
    if effect in ("joint_coupling", "wrist_coupling") and "->" in base:
        src, dst = (int(x[1]) - 1 for x in base.split("->"))
        if quad:
            return [("quad_coupling", {"pair": (src, dst)}, 1e-4)]
        return [("coupling", {"pair": (src, dst)}, 1e-4)]
    if effect == "coupling_difference" and " on " in base:  # "Ji-Jj on Jj"
        other, dst = (int(x[1]) - 1 for x in base.split(" on ")[0].split("-"))
        return [("difference", {"pair": (other, dst)}, 1e-4)]
    return None


ALIKE_SHARE = 0.9  # robocal's near-collinear bound (`stepwise.LOOK_ALIKE_SHARE`): a rival explaining 90 % of the effect
ALPHA = 0.01  # the diagnosis's level (`Settings.alpha`): a swap the fit cannot reject at it is a look-alike


def collinear_share(w: World, S_true: np.ndarray, payload_kg, effect: str, location: str) -> float | None:
    """The share of the true effect's signature ⊥ the geometry that the generator's own forms of `effect@location`
    span (⊥ the geometry) on this campaign; None where the generator has no form of that name."""
    fs = _forms_of(effect, location)
    if fs is None:
        return None
    _, J = w.clean(payload_kg)
    B = np.stack([_perp(true_signature(w, k, wh, u, payload_kg, False), J) for k, wh, u in fs], axis=1)
    St = _perp(S_true, J)
    U, sv, _ = np.linalg.svd(B, full_matrices=False)
    U = U[:, sv > sv[0] * 1e-9]
    return float(np.sum((U.T @ St) ** 2) / (St @ St))


def collinear_alike(d: dict, key, w: World, S_true: np.ndarray, payload_kg, size: float) -> dict:
    """Where the right name is not a finding but reported beside a lower-than-high-confidence finding
    (`named_beside`): the generator's share of the true signature ⊥ geometry that the finding's name spans
    (`share`), the swap's noncentrality at the injected `size` (`swap_chi2`: (1 − share)·‖P⊥S‖²·size²/σ², the
    expected Δχ² by which the true name fits better, noise-free) and whether the two are look-alikes by robocal's
    own two measures, computed from the truth (`collinear`): near-collinear (share ≥ `ALIKE_SHARE`,
    `stepwise.LOOK_ALIKE_SHARE`), or a swap the data cannot reject at the diagnosis's level at this size
    (`swap_chi2` below χ²_k(1 − α), k the finding's parameters: `method._alike_evidence`'s and
    `method._choose_names`' bound).  Either way both names with lowered confidence is the right answer; a
    listed name beyond both is a miss."""
    for f in d["findings"]:
        if f["confidence"] == "high" or right(f, key):
            continue
        if any(right(a, key) for a in f.get("look_alikes", []) + f.get("untested_look_alikes", [])):
            sh = collinear_share(w, S_true, payload_kg, f["effect"], f["location"])
            _, J = w.clean(payload_kg)
            lam = None if sh is None else (1 - sh) * float(np.sum(_perp(S_true, J) ** 2)) * size**2 / SIGMA**2
            crit = float(scipy.stats.chi2.ppf(1 - ALPHA, len(f["parameters"])))
            return {"finding": f"{f['effect']}@{f['location']}", "share": sh, "swap_chi2": lam, "chi2_crit": crit,
                    "near_collinear": sh is not None and sh >= ALIKE_SHARE,
                    "collinear": sh is not None and (sh >= ALIKE_SHARE or lam < crit)}
    return {"finding": None, "share": None, "swap_chi2": None, "near_collinear": False, "collinear": False}


def named_beside(d: dict, key) -> bool:
    """The right effect is a finding, or a look-alike reported beside a finding of lower than high confidence (the
    campaign cannot tell the two apart: both are named, with their evidence; or the gate could not test it here and
    it would explain the finding as well)."""
    return any(right(f, key) or (f["confidence"] != "high" and any(
        right(a, key) for a in f.get("look_alikes", []) + f.get("untested_look_alikes", [])))
               for f in d["findings"])


def score(d: dict, key, second=None, out_of_library=None) -> dict:
    ok = [key] + ([second] if second else [])
    named = [any(right(f, k) for f in d["findings"]) for k in ok]
    return {"status": d["status"], "named": bool(named[0]), "named_second": bool(named[-1]) if second else None,
            "named_or_alike": named_beside(d, key) if key else None,
            "named_or_alike_second": named_beside(d, second) if second else None,
            "named_high": any(right(f, key) and f["confidence"] == "high" for f in d["findings"]),
            "misnamed_high": any(f["confidence"] == "high" and not any(right(f, k) for k in ok) for f in d["findings"]),
            "false": len(d["findings"]) if key is None and out_of_library is None else 0,
            "located": located_right(d, *out_of_library) if out_of_library else None,
            "worse": d["holdout_rms_after_m"] > d["holdout_rms_before_m"] + 1e-15,
            "findings": [f"{f['effect']}@{f['location']}:{f['confidence']}" for f in d["findings"]],
            "where": [u["variable"] for u in d["unexplained_where"]][:3]}


def run_one(w: World, name: str, mult: float, n_boot: int) -> dict:
    """One case on one seed's campaign at mult × the ideal MDE (of each effect, for a pair)."""
    effects, payload, unit, key = CASES[name]
    effs, mdes = [], []
    for kind, where in effects:
        where = placed(w, kind, where)
        m, _ = ideal_mds(w, kind, where, payload, unit if kind != "backlash" else None, mult)
        effs.append(it.Effect(kind, mult * m, where))
        mdes.append(m)
    c = isr.run(w.nom, w.tru, w.plan(payload), tuple(effs), seed=w.seed, stream_noise_counts=w.stream_noise)
    d = diagnose(aw.TouchModel(aw.nominal_arm()), diagnosis_table(c),
                 settings=Settings(n_boot=n_boot, repeatability_3sigma_m=REPEATABILITY))
    ool = (effects[0][0], effs[0].where) if key is None else None
    r = {"seed": w.seed, "mds_ideal": mdes, "size": [e.size for e in effs], **score(d, key, SECOND.get(name), ool)}
    r["named_or_collinear_alike"] = r["named_or_near_collinear"] = None if key is None else r["named"]
    if key is not None and not r["named"] and r["named_or_alike"]:  # a pair: its first effect, the one `key` names
        kind, where = effects[0]
        _, S = ideal_mds(w, kind, placed(w, kind, where), payload, unit if kind != "backlash" else None, mult)
        r["alike"] = collinear_alike(d, key, w, S, payload, effs[0].size)
        r["named_or_collinear_alike"] = r["alike"]["collinear"]
        r["named_or_near_collinear"] = r["alike"]["near_collinear"]
    return {**r, "_doc": d}


def clean_run(w: World, n_boot: int) -> dict:
    c = isr.run(w.nom, w.tru, w.sc, (), seed=w.seed, stream_noise_counts=w.stream_noise)
    d = diagnose(aw.TouchModel(aw.nominal_arm()), diagnosis_table(c),
                 settings=Settings(n_boot=n_boot, repeatability_3sigma_m=REPEATABILITY))
    return {"seed": w.seed, **score(d, None), "_doc": d}


def budget(w: World, name: str, clean_doc: dict | None = None) -> dict | None:
    """The power budget of an in-library case on this seed's campaign (module docstring), from robocal's
    linearised problem on the clean noisy campaign."""
    from pipeline.diagnose.adapters.touch import touch_adapter
    from pipeline.diagnose.inference import screen
    from pipeline.diagnose.inference.gate import gate
    from pipeline.diagnose.inference.projection import orthonormal, project_out
    from pipeline.diagnose.method import _geometry

    effects, payload, unit, key = CASES[name]
    if key is None or len(effects) > 1:
        return None
    kind, where = effects[0]
    where = placed(w, kind, where)
    m_ideal, S_true = ideal_mds(w, kind, where, payload, unit if kind != "backlash" else None, 4.0)
    c = isr.run(w.nom, w.tru, w.plan(payload), (), seed=w.seed, stream_noise_counts=w.stream_noise)
    model = aw.TouchModel(aw.nominal_arm())
    tab = diagnosis_table(c)
    ad = touch_adapter(model, tab, 2e-5, None, REPEATABILITY)
    f = _geometry(model, tab, ad, None, None)
    p = screen.problem(model, tab, f, ad)
    gs = gate(p.lib, p.S, p.Jf, p.free_names, p.sigma, 0.01)
    m = sum(g.identifiable for g in gs)
    fam = [i for i, e in enumerate(p.lib) if right({"effect": e.name, "location": str(e.location)}, key)]
    Q = orthonormal(p.Jf)
    St = project_out(S_true[:, None], Q)[:, 0]
    capture, best = 0.0, None
    for i in fam:
        B = orthonormal(project_out(p.S[i], Q))
        cap = float(np.linalg.norm(B.T @ St) / max(np.linalg.norm(St), 1e-300))
        if cap > capture:
            capture, best = cap, i
    z = float(scipy.stats.norm.ppf(1 - 0.01 / (2 * m)))
    _, J = w.clean(payload)
    gen_norm = float(np.linalg.norm(_perp(S_true, J)))
    rob_norm = float(np.linalg.norm(St))
    ideal80 = (3 + Z80) * SIGMA / gen_norm
    eff80 = (z + Z80) * p.sigma / max(capture * rob_norm, 1e-300)
    gate_mds = gs[best].min_detectable if best is not None else None
    gate_thr = gs[best].threshold if best is not None else None
    phases = (phase_budget(w, where, payload, unit, gs[best], p.sigma, capture * rob_norm, len(p.lib), m)
              if best is not None and kind == "eccentricity" else None)
    return {"phases": phases, "mds_ideal_t3": m_ideal, "mds_ideal_80": ideal80, "mds_robocal_gate": gate_mds,
            "mds_robocal_effective": eff80, "ratio_gate": (gate_mds or np.inf) / ideal80,
            "ratio_effective": eff80 / ideal80,
            # the same in the ideal's convention (50 % power): robocal's critical value vs t = 3
            "threshold_robocal_gate": gate_thr, "ratio_threshold_gate": (gate_thr or np.inf) / m_ideal,
            "best_form": str(p.lib[best].location) if best is not None else None,
            "factors": {"multiplicity": (z + Z80) / (3 + Z80), "m": m, "sigma": p.sigma / SIGMA,
                        "geometry": gen_norm / rob_norm, "capture": capture}}


def chi2_power_scale(k: int, level: float, power: float = 0.8) -> float:
    """√λ of the noncentral χ²_k whose test at `level` has `power`: the detectable size of a k-parameter effect, in
    σ over its projected signature's norm along its direction (k = 1: ≈ z_{1−level/2} + z_power)."""
    crit = scipy.stats.chi2.ppf(1 - level, k)
    return float(np.sqrt(scipy.optimize.brentq(lambda lam: scipy.stats.ncx2.sf(crit, k, lam) - power, 1e-6, 1e4)))


def phase_budget(w: World, where: dict, payload, unit: float, g, sigma_hat: float, captured_norm: float,
                 m_library: int, m_tested: int) -> dict:
    """A two-parameter (phase-unknown) term's budget like for like, at one phase at a time: at the injected phase
    and at robocal's weakest one (its gate's figure is along that direction), the ideal (the phase known, 1 dof,
    80 %: (3 + z₀.₈)σ/‖P⊥S_φ‖, the generator's signature at φ) beside robocal's 80 % figures at that phase — its
    gate's own (the figure `min_detectable` states) and, computed here, its χ² test over both phases (the grouped F
    it runs, 2 dof, at Holm's first threshold α/m over the candidates it tests: the honest detectable amplitude of
    an effect whose phase it does not know).  The gate states that same test, so the two agree.  The generator's eccentricity
    A·sin(q + φ) is robocal's a·cos q + b·sin q with (a, b) = A·(sin φ, cos φ)."""
    _, J = w.clean(payload)
    _, sv, Vt = np.linalg.svd(g.projected, full_matrices=False)
    a, b = Vt[-1]
    weak = float(np.arctan2(a, b))

    def ideal80(phase):
        S = true_signature(w, "eccentricity", {**where, "phase": phase}, unit, payload, False)
        return (3 + Z80) * SIGMA / np.linalg.norm(_perp(S, J))

    z_lib = float(scipy.stats.norm.ppf(1 - ALPHA / (2 * m_library))) + Z80
    k2 = chi2_power_scale(2, ALPHA / m_tested)
    inj, wk = ideal80(where["phase"]), ideal80(weak)
    return {"injected": {"phase": where["phase"], "ideal_80": inj,
                         "robocal_chi2_2dof": k2 * sigma_hat / captured_norm,
                         "ratio_chi2_2dof": k2 * sigma_hat / captured_norm / inj},
            "weakest": {"phase": weak, "ideal_80": wk, "robocal_gate": g.min_detectable,
                        "ratio_gate": g.min_detectable / wk,
                        "robocal_chi2_2dof": k2 * sigma_hat / sv[-1] + g.effect.tolerance,
                        "ratio_chi2_2dof": (k2 * sigma_hat / sv[-1] + g.effect.tolerance) / wk},
            "z_library": z_lib, "chi2_scale_tested": k2}


def _rate(rows, k):
    v = [r[k] for r in rows if r.get(k) is not None]
    return float(np.mean(v)) if v else None


def report(seeds, mults=(4.0, 2.0), names=None, n_boot: int = 20, clean: bool = True, budgets: bool = True,
           out: list | None = None, stream_noise_counts: float = 1.0, clean_only: bool = False,
           budget_only: bool = False, save: str = ""):
    """Run every case on every seed's campaign; print one JSON line per case and multiple (and the budget per
    in-library case) as it goes; return the summary."""
    import json
    import time

    names = names or list(CASES)
    rows: dict = {}
    t0 = time.time()
    for s in seeds:
        w = World(s, stream_noise_counts=stream_noise_counts)
        if clean and not budget_only:
            r = clean_run(w, n_boot)
            r.pop("_doc")
            rows.setdefault(("clean", 0.0), []).append(r)
        for name in [] if clean_only else names:
            if budgets:
                b = budget(w, name)
                if b:
                    rows.setdefault((name, "budget"), []).append(b)
            for mult in () if budget_only else mults:
                r = run_one(w, name, mult, n_boot)
                r.pop("_doc")
                rows.setdefault((name, mult), []).append(r)
        print(json.dumps({"seed": s, "elapsed_s": round(time.time() - t0)}), flush=True)
        if save:  # every seed's rows so far (a long run that stops keeps what it measured)
            with open(save, "w") as fh:
                json.dump({f"{k[0]} {k[1]}": v for k, v in rows.items()}, fh, default=float)
    summary = {}
    for (name, mult), rr in rows.items():
        if mult == "budget":
            med = {k: float(np.median([r[k] for r in rr])) for k in ("mds_ideal_t3", "mds_ideal_80", "mds_robocal_gate",
                                                                       "mds_robocal_effective", "ratio_gate",
                                                                       "ratio_effective", "threshold_robocal_gate",
                                                                       "ratio_threshold_gate")}
            med.update({f"{k}_max": float(np.max([r[k] for r in rr])) for k in ("ratio_gate", "ratio_threshold_gate")})
            med["seeds"] = len(rr)
            med["factors"] = {k: float(np.median([r["factors"][k] for r in rr])) for k in rr[0]["factors"]}
            med["forms"] = sorted({r["best_form"] for r in rr if r["best_form"]})
            ph = [r["phases"] for r in rr if r.get("phases")]
            if ph:  # a two-parameter term at one phase at a time (`phase_budget`): medians and worst seeds
                med["phases"] = {f"{at} {k}": (float(np.median([x[at][k] for x in ph])),
                                               float(np.max([x[at][k] for x in ph])))
                                 for at in ("injected", "weakest") for k in ph[0][at] if k != "phase"}
            summary[f"{name} budget"] = med
        else:
            summary[f"{name} {mult:g}x"] = {
                "runs": len(rr), **{k: _rate(rr, k) for k in ("named", "named_or_near_collinear", "named_or_collinear_alike", "named_or_alike", "named_second",
                                                             "named_or_alike_second",
                                                             "named_high", "misnamed_high", "located", "worse")},
                "false_findings": int(sum(r["false"] for r in rr)) if name == "clean" else None,
                "statuses": {k: sum(r["status"] == k for r in rr) for k in sorted({r["status"] for r in rr})},
                "alike_shares": [round(r["alike"]["share"], 4) if r["alike"]["share"] is not None else None
                                 for r in rr if r.get("alike")],
                "alike_swap_chi2": [round(r["alike"]["swap_chi2"], 2) if r["alike"].get("swap_chi2") is not None
                                    else None for r in rr if r.get("alike")],
                "misses": [(r["seed"], r["findings"], r["where"]) for r in rr
                           if name != "clean"
                           and not (r["located"] if r.get("located") is not None else r.get("named_or_collinear_alike"))][:6]}
        key = f"{name} budget" if mult == "budget" else f"{name} {mult:g}x"
        print(json.dumps({key: summary[key]}), flush=True)
    if out is not None:
        out.append(rows)
    return summary


def markdown(summary: dict) -> str:
    """The summary as the tables the guide shows: per in-library case and multiple the share of seeds naming it
    (strictly; or as a look-alike beside a lower-confidence finding of a near-collinear name, `named_or_near_collinear`,
    or of a name the data cannot tell from it at that size, `named_or_collinear_alike`),
    named `high`, misnamed `high`, worse than geometry; per out-of-library case located; clean campaigns' false
    findings."""
    n = 0

    def pct(v):
        return "–" if v is None else f"{round(v * n)}/{n}"

    rows = ["| case | × ideal MDE | seeds | named | named or near-collinear look-alike | named or look-alike the data "
            "cannot separate | named `high` | misnamed `high` | second effect named | worse than geometry | statuses |",
            "|---|---|---|---|---|---|---|---|---|---|---|"]
    out_rows = ["| case | × ideal MDE | seeds | located | misnamed `high` | worse than geometry | statuses |",
                "|---|---|---|---|---|---|---|"]
    clean = []
    budget = ["| term (SI units) | seeds | ideal, t = 3 | ideal, 80 % | robocal gate, 80 % | robocal / ideal (80 %): median, max "
              "| threshold / ideal t = 3: median, max |", "|---|---|---|---|---|---|---|"]
    phases = ["| term | at the phase | ideal, 80 % (phase known) | robocal gate, 80 % | gate / ideal: median, max "
              "| robocal's χ² over both phases, 80 % | χ² / ideal: median, max |", "|---|---|---|---|---|---|---|"]
    for k, v in summary.items():
        if k.endswith("budget") and v.get("phases"):
            ph = v["phases"]
            for at in ("injected", "weakest"):
                gate = (f"{ph['weakest robocal_gate'][0]:.3g} | {ph['weakest ratio_gate'][0]:.2f}, "
                        f"{ph['weakest ratio_gate'][1]:.2f}" if at == "weakest" else "– | –")
                phases.append(f"| {k[:-7]} | {at} | {ph[f'{at} ideal_80'][0]:.3g} | {gate} "
                              f"| {ph[f'{at} robocal_chi2_2dof'][0]:.3g} | {ph[f'{at} ratio_chi2_2dof'][0]:.2f}, "
                              f"{ph[f'{at} ratio_chi2_2dof'][1]:.2f} |")
        if k.endswith("budget"):
            budget.append(f"| {k[:-7]} | {v.get('seeds', '')} | {v['mds_ideal_t3']:.3g} | {v['mds_ideal_80']:.3g} "
                          f"| {v['mds_robocal_gate']:.3g} | {v['ratio_gate']:.2f}, {v.get('ratio_gate_max', np.nan):.2f} "
                          f"| {v['ratio_threshold_gate']:.2f}, {v.get('ratio_threshold_gate_max', np.nan):.2f} |")
            continue
        name, mult = k.rsplit(" ", 1)
        n = v["runs"]
        st = ", ".join(f"{a} {b}" for a, b in v["statuses"].items())
        if name == "clean":
            clean.append(f"clean campaigns: {v['runs']} seeds, {v['false_findings']} false findings ({st})")
        elif v.get("located") is not None:
            out_rows.append(f"| {name} | {mult} | {v['runs']} | {pct(v['located'])} | {pct(v['misnamed_high'])} "
                            f"| {pct(v['worse'])} | {st} |")
        else:
            rows.append(f"| {name} | {mult} | {v['runs']} | {pct(v['named'])} | {pct(v.get('named_or_near_collinear'))} "
                        f"| {pct(v.get('named_or_collinear_alike'))} "
                        f"| {pct(v['named_high'])} | {pct(v['misnamed_high'])} | {pct(v.get('named_second'))} "
                        f"| {pct(v['worse'])} | {st} |")
    parts = [rows if len(rows) > 2 else [], out_rows if len(out_rows) > 2 else [], budget if len(budget) > 2 else [],
             phases if len(phases) > 2 else [], clean]
    return "\n\n".join("\n".join(p) for p in parts if p)
