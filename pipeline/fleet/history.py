"""Each robot's calibrations over time (functional core of `robocal fleet`): parameter series with σ,
steps between consecutive calibrations, trends (drift), accuracy against a tolerance, and the
recordings that failed or were insufficient.

Steps: |x_k − x_{k−1}| > c·√(σ_k² + σ_{k−1}²), with c = max(3, t quantile at α/(2m)) — 3σ, raised by
Bonferroni over the robot's m comparisons (family α per robot, default 1 %) and by Student's t with the
Welch–Satterthwaite degrees of freedom of the two σ (each σ is estimated from that fit's residuals).
Trends: weighted least squares of each parameter on time with one level per segment between flagged
steps of that parameter; the slope's standard error scaled by the Birge ratio √(χ²/dof) when above 1;
flagged when |slope/se| exceeds the t quantile at α/(2P) (P parameters tested for the robot).

A change of the identified set (a parameter fitted in one calibration and held in the next, or the
reverse) is news about the campaign, not about the robot (`free_set_changes`).  Across such a change
the other parameters may absorb what a held one no longer explains, so a move there is a step only
when it is *confirmed on a common basis*: the first later calibration whose identified set also
occurs before the change is compared with the latest earlier calibration of that same set, at the
same threshold.  A confirmed step carries the change (`free_set_change`, `confirmed_by`); an
unconfirmed move is listed with the change (`moved`), not as a step.  (In a simulated fleet the rank
test swaps dependent pairs such as J2.d / J3.d from one month to the next and a real step coincides
with such a swap: the sets recur, so the step is confirmed.)
"""

from __future__ import annotations

from collections import Counter, defaultdict
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

FAILED = ("fail", "error", "crash", "lost")
NS_PER_YEAR = 365.25 * 86400e9
UNKNOWN = "(no robot id)"


@dataclass
class Series:
    """One parameter of one robot over its usable calibrations (SI units)."""

    name: str
    unit: str
    t_ns: np.ndarray
    estimate: np.ndarray
    std: np.ndarray
    dof: np.ndarray  # residual degrees of freedom of each σ (inf when unknown)
    recordings: list[str]


@dataclass
class RobotHistory:
    robot_id: str
    rows: list[dict]                      # every row of the robot, in campaign-time order
    usable: list[dict]                    # rows the series are built from
    series: dict[str, Series] = field(default_factory=dict)
    steps: list[dict] = field(default_factory=list)
    free_set_changes: list[dict] = field(default_factory=list)  # identified set changed between calibrations
    trends: list[dict] = field(default_factory=list)
    tolerance: list[dict] = field(default_factory=list)
    failed: list[dict] = field(default_factory=list)
    insufficient: list[dict] = field(default_factory=list)

    @property
    def flagged(self) -> bool:
        return bool(self.steps or self.trends or self.tolerance)


def insufficiency(row: dict, usual_identifiable: int | None) -> str | None:
    """Why a completed calibration cannot enter the history, or None: no time or parameters, or fewer
    than 90 % of the robot's usual number of identifiable parameters (a campaign that does not
    determine the model).  A parameter fixed in one calibration only drops out of that comparison."""
    if row.get("campaign_start_ns") is None:
        return "no campaign time"
    if not row.get("parameters"):
        return "no parameters"
    if usual_identifiable is not None and (row.get("n_identifiable") or 0) < 0.9 * usual_identifiable:
        return f"{row.get('n_identifiable')} identifiable parameters, {usual_identifiable} usually: the campaign " \
               "does not determine the robot's model"
    if (row.get("residual_dof") or 0) < 1:
        return "no residual degrees of freedom"
    return None


def build_series(rows: list[dict]) -> dict[str, Series]:
    names: dict[str, str] = {}
    for r in rows:
        for p in r["parameters"]:
            if p["identifiable"] and p.get("std") is not None and np.isfinite(p["std"]):
                names.setdefault(p["name"], p["unit"])
    out = {}
    for name, unit in names.items():
        t, x, s, d, rec = [], [], [], [], []
        for r in rows:
            p = next((p for p in r["parameters"] if p["name"] == name), None)
            if p is None or not p["identifiable"] or p.get("std") is None or not np.isfinite(p["std"]):
                continue
            t.append(r["campaign_start_ns"])
            x.append(p["estimate"])
            s.append(p["std"])
            d.append(r.get("residual_dof") or np.inf)
            rec.append(r["recording"])
        out[name] = Series(name, unit, np.asarray(t, np.int64), np.asarray(x, float), np.asarray(s, float),
                           np.asarray(d, float), rec)
    return out


def welch_dof(s1: np.ndarray, n1: np.ndarray, s2: np.ndarray, n2: np.ndarray) -> np.ndarray:
    """Welch–Satterthwaite degrees of freedom of √(s1² + s2²)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        v = (s1**2 + s2**2) ** 2 / (s1**4 / n1 + s2**4 / n2)
    return np.where(np.isfinite(v), v, np.inf)


def identified_set(row: dict) -> frozenset[str]:
    """Names of the parameters a calibration identified (fitted, with a finite σ)."""
    return frozenset(p["name"] for p in row.get("parameters") or []
                     if p.get("identifiable") and p.get("std") is not None and np.isfinite(p["std"]))


def free_set_changes(rows: list[dict]) -> list[dict]:
    """Consecutive usable calibrations whose identified sets differ: {recording, from_recording,
    t_ns, from_t_ns, freed, held} (names newly fitted, names no longer fitted)."""
    out = []
    for a, b in zip(rows, rows[1:]):
        sa, sb = identified_set(a), identified_set(b)
        if sa != sb:
            out.append({"recording": b["recording"], "from_recording": a["recording"], "t_ns": b["campaign_start_ns"],
                        "from_t_ns": a["campaign_start_ns"], "freed": sorted(sb - sa), "held": sorted(sa - sb)})
    return out


def _threshold(s1, n1, s2, n2, p: float) -> np.ndarray:
    """c = max(3, t quantile at p with the Welch–Satterthwaite dof of √(s1² + s2²))."""
    nu = welch_dof(s1, n1, s2, n2)
    return np.maximum(3.0, np.where(np.isfinite(nu), stats.t.isf(p, np.where(np.isfinite(nu), nu, 1)),
                                    stats.norm.isf(p)))


def _confirm(s: Series, k: int, sets: dict[str, frozenset], p: float) -> dict | None:
    """For a move between series entries k and k+1 across a change of the identified set: the first
    entry l > k whose set also occurs at some entry j ≤ k (the latest such j), and whether x_l − x_j
    exceeds the threshold — {from_recording, recording, delta, sigma, z, threshold, confirmed} — or
    None when no set recurs on both sides."""
    for li in range(k + 1, s.estimate.size):
        same = [j for j in range(k + 1) if sets.get(s.recordings[j]) == sets.get(s.recordings[li])]
        if not same:
            continue
        j = same[-1]
        d = float(s.estimate[li] - s.estimate[j])
        sd = float(np.hypot(s.std[li], s.std[j]))
        crit = float(_threshold(s.std[li:li + 1], s.dof[li:li + 1], s.std[j:j + 1], s.dof[j:j + 1], p)[0])
        return {"from_recording": s.recordings[j], "recording": s.recordings[li], "delta": d, "sigma": sd,
                "z": d / sd, "threshold": crit, "confirmed": bool(abs(d / sd) > crit)}
    return None


def find_steps(series: dict[str, Series], alpha: float = 0.01,
               changed: dict[tuple[str, str], dict] | None = None,
               sets: dict[str, frozenset] | None = None) -> tuple[list[dict], list[dict]]:
    """(steps, moves): moves between consecutive calibrations of a parameter beyond the threshold
    (module docstring).  A move between recordings whose identified sets differ (`sets`: recording →
    identified set; `changed`: the consecutive pairs that differ) is a step only when confirmed on a
    common basis (`_confirm`); otherwise it is returned in `moves` (news, not a step)."""
    changed, sets = changed or {}, sets or {}
    m = sum(max(0, s.estimate.size - 1) for s in series.values())
    if m == 0:
        return [], []
    p = alpha / (2 * m)
    steps, moves = [], []
    for s in series.values():
        if s.estimate.size < 2:
            continue
        d = np.diff(s.estimate)
        sd = np.hypot(s.std[1:], s.std[:-1])
        crit = _threshold(s.std[1:], s.dof[1:], s.std[:-1], s.dof[:-1], p)
        z = d / sd
        for k in np.flatnonzero(np.abs(z) > crit):
            a, b = s.recordings[k], s.recordings[k + 1]
            row = {"param": s.name, "unit": s.unit, "index": int(k + 1), "t_ns": int(s.t_ns[k + 1]),
                   "from_t_ns": int(s.t_ns[k]), "recording": b, "delta": float(d[k]), "sigma": float(sd[k]),
                   "z": float(z[k]), "threshold": float(crit[k])}
            if sets.get(a, frozenset()) == sets.get(b, frozenset()) and (a, b) not in changed:
                steps.append(row)
                continue
            fa, fb = sets.get(a, frozenset()), sets.get(b, frozenset())
            c = changed.get((a, b)) or {"freed": sorted(fb - fa), "held": sorted(fa - fb)}
            row["free_set_change"] = {"freed": c["freed"], "held": c["held"]}
            check = _confirm(s, int(k), sets, p)
            if check is not None and check["confirmed"]:
                steps.append(row | {"confirmed_by": check})
            else:
                moves.append(row | ({"checked_by": check} if check else {}))
    return steps, moves


def fit_trend(s: Series, step_indices: list[int]) -> dict | None:
    """Weighted LS: one level per segment (split at `step_indices`), one slope (per year)."""
    n = s.estimate.size
    seg = np.searchsorted(np.asarray(sorted(step_indices), int), np.arange(n), side="right")
    n_seg = int(seg.max()) + 1 if n else 0
    dof = n - n_seg - 1
    if dof < 2:
        return None
    ty = (s.t_ns - s.t_ns[0]) / NS_PER_YEAR
    A = np.zeros((n, n_seg + 1))
    A[np.arange(n), seg] = 1.0
    A[:, -1] = ty
    w = 1.0 / s.std
    Aw, yw = A * w[:, None], s.estimate * w
    coef, *_ = np.linalg.lstsq(Aw, yw, rcond=None)
    cov = np.linalg.pinv(Aw.T @ Aw)
    chi2 = float(np.sum((yw - Aw @ coef) ** 2))
    birge = max(1.0, chi2 / dof)
    se = float(np.sqrt(cov[-1, -1] * birge))
    return {"param": s.name, "unit": s.unit, "slope_per_year": float(coef[-1]), "se_per_year": se,
            "z": float(coef[-1] / se) if se > 0 else 0.0, "dof": dof, "chi2_dof": chi2 / dof,
            "levels": coef[:-1].tolist(), "segments": seg.tolist()}


def find_trends(series: dict[str, Series], steps: list[dict], alpha: float = 0.01) -> list[dict]:
    fits = []
    for s in series.values():
        f = fit_trend(s, [st["index"] for st in steps if st["param"] == s.name])
        if f is not None:
            fits.append(f)
    if not fits:
        return []
    p = alpha / (2 * len(fits))
    out = []
    for f in fits:
        crit = float(stats.t.isf(p, f["dof"]))
        if abs(f["z"]) > crit:
            out.append(f | {"threshold": crit})
    return out


def robot_history(robot_id: str, rows: list[dict], tolerance_m: float | None, alpha: float = 0.01) -> RobotHistory:
    rows = sorted(rows, key=lambda r: (r.get("campaign_start_ns") is None, r.get("campaign_start_ns") or 0,
                                       r["recording"]))
    h = RobotHistory(robot_id, rows, [])
    done = [r for r in rows if r.get("status") not in FAILED]
    h.failed = [r for r in rows if r.get("status") in FAILED]
    counts = Counter(r.get("n_identifiable") for r in done if r.get("parameters"))
    usual = max(counts, key=lambda k: (counts[k], k or 0)) if counts else None
    for r in done:
        why = insufficiency(r, usual)
        if why:
            h.insufficient.append(r | {"reason": why})
        else:
            h.usable.append(r)
    h.series = build_series(h.usable)
    h.free_set_changes = free_set_changes(h.usable)
    changed = {(c["from_recording"], c["recording"]): c for c in h.free_set_changes}
    h.steps, moves = find_steps(h.series, alpha, changed, {r["recording"]: identified_set(r) for r in h.usable})
    for c in h.free_set_changes:
        c["moved"] = []
    for mv in moves:  # an unconfirmed move is listed with the (last) change it crossed
        crossed = [c for c in h.free_set_changes if mv["from_t_ns"] < c["t_ns"] <= mv["t_ns"]]
        if crossed:
            crossed[-1]["moved"].append({k: mv[k] for k in ("param", "unit", "delta", "sigma", "z", "from_t_ns",
                                                           "t_ns")} | {k: mv[k] for k in ("checked_by",) if k in mv})
    h.trends = find_trends(h.series, h.steps + moves, alpha)  # a level per segment, unconfirmed moves included
    if tolerance_m is not None:
        h.tolerance = [{"recording": r["recording"], "t_ns": r["campaign_start_ns"], "holdout_rms_m": r["holdout_rms_m"]}
                       for r in h.usable if r.get("holdout_rms_m") is not None and r["holdout_rms_m"] > tolerance_m
                       and r.get("residual_unit") in (None, "m")]  # a length tolerance: px runs are not compared
    return h


def fleet_history(rows: list[dict], tolerance_m: float | None = None, alpha: float = 0.01) -> list[RobotHistory]:
    """One history per robot (rows without a robot id are grouped under UNKNOWN), sorted by id."""
    by: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        by[r.get("robot_id") or UNKNOWN].append(r)
    return [robot_history(k, by[k], tolerance_m, alpha) for k in sorted(by)]
