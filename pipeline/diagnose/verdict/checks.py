"""The diagnosis' verdict: what may be reported as found and with what confidence.

Pure functions of (residuals, designs, tables):

- **held-out arbiter** (`arbiter`): a finding is reported as found only if modelling it lowers the
  grouped cross-validated RMS; if the final model is worse out of sample than geometry alone,
  nothing is reported as found;
- **back to the floor** (`floor_check`): the residuals after modelling against the noise floor the
  campaign supports (robot repeatability, encoder quantisation, jig machining), χ² test;
- **misspecification** (`misspecified`): a named effect whose own variable still shows structure
  beside it (a flexible basis along that variable adds significantly) is not high confidence;
- **influence** (`studentized_outliers`, `implausible_speed`, `carried_by`): records far off the
  geometric fit or with a physically impossible derived quantity, and findings that lose their
  significance when one or two records are left out, are reported as outliers of those records;
- **status** (`status`): clean / explained / partially_explained / unexplained /
  model_worse_out_of_sample.
"""

from __future__ import annotations

import numpy as np
import scipy.stats

from pipeline.diagnose.inference.projection import orthonormal, project_out
from pipeline.diagnose.verdict.lack_of_fit import grouped_p
from pipeline.ingest.context import ENCODER_COUNT_RAD

# a touch search runs at mm/s to a few cm/s; a derived approach speed above this is not a search
MAX_SEARCH_SPEED_M_S = 0.25


def touch_floor_variance(Jq_axis: np.ndarray, repeatability_3sigma_m: float, jig_tolerance_m: float,
                         count_rad: float = ENCODER_COUNT_RAD) -> np.ndarray:
    """Per-contact noise-floor variance (n,) m² along the measured axis: the robot's repeatability
    (3σ, isotropic), each joint's encoder quantisation (uniform within one count, through the
    joint Jacobian row `Jq_axis` (n, n_joints) m/rad) and the face's machining error (uniform
    within ± the jig tolerance)."""
    return ((repeatability_3sigma_m / 3) ** 2 + np.sum(Jq_axis**2, axis=1) * count_rad**2 / 12
            + jig_tolerance_m**2 / 3)


def floor_check(r: np.ndarray, dof: int, var_floor: np.ndarray, alpha: float) -> dict:
    """χ² test of residuals r (n,) with `dof` residual degrees of freedom against the floor
    variances (n,): `above_floor` when Σ r²/v exceeds χ²_dof's 1 − α quantile."""
    q = float(np.sum(np.asarray(r, float) ** 2 / var_floor))
    dof = max(int(dof), 1)
    p = float(scipy.stats.chi2.sf(q, dof))
    return {"sigma_floor_m": float(np.sqrt(np.mean(var_floor))), "rms_over_floor": float(np.sqrt(q / dof)),
            "dof": dof, "p_value": p, "above_floor": bool(p < alpha),
            "test": "chi-square of the residuals after modelling over the declared noise floor"}


def holdout_floor_check(A: np.ndarray, e_cv: np.ndarray, folds: list[np.ndarray], var_floor: np.ndarray,
                        alpha: float) -> dict:
    """The held-out residuals e_cv (`resampling.holdout` of design A) against the floor: with the rows'
    errors ε ~ N(0, diag v) and the model right, e_cv = (I − P)ε (P: each fold predicted from the
    others' fit, which reproduces any A·β exactly), so ‖e_cv‖² is a quadratic form in ε whose mean
    tr(QV) and variance 2 tr((QV)²) (Q = (I − P)ᵀ(I − P)) give a scaled χ² (Satterthwaite)."""
    n = e_cv.size
    norms = np.linalg.norm(A, axis=0)
    As = A / np.where(norms == 0, 1, norms)
    P = np.zeros((n, n))
    for test in folds:
        train = np.setdiff1d(np.arange(n), test)
        P[np.ix_(test, train)] = As[test] @ np.linalg.pinv(As[train], rcond=1e-10)
    rows = np.sort(np.concatenate(folds))  # rows in no fold are not predicted (`resampling.design_folds`)
    R = (np.eye(n) - P)[rows]
    e_cv = e_cv[rows]
    QV = (R.T @ R) * var_floor[None, :]
    m1, m2 = float(np.trace(QV)), float(np.sum(QV * QV.T))
    g, h = m2 / m1, m1**2 / m2
    T = float(e_cv @ e_cv)
    p = float(scipy.stats.chi2.sf(T / g, h))
    return {"holdout_rms_expected_at_floor_m": float(np.sqrt(m1 / rows.size)), "holdout_p_value": p,
            "holdout_above_floor": bool(p < alpha)}


def studentized_outliers(J: np.ndarray, r: np.ndarray, alpha: float, max_out: int | None = None) -> list[tuple[int, float]]:
    """Rows whose externally studentized residual (design J, residual r ⊥ J) is beyond the
    Bonferroni bound at family α (t with n − p − 1 dof), one at a time: the most extreme row is
    set aside and the rest re-tested without it (so one gross error neither masks nor drags
    others over the bound).  At most `max_out` rows (default 5 % of them): [(row, t)]."""
    r = np.asarray(r, float)
    n = r.size
    max_out = max(1, n // 20) if max_out is None else max_out
    alive = np.ones(n, bool)
    out: list[tuple[int, float]] = []
    while len(out) < max_out:
        idx = np.flatnonzero(alive)
        Q = orthonormal(J[idx])
        e = project_out(r[idx][:, None], Q)[:, 0]
        h = np.clip(np.sum(Q**2, axis=1), 0, 1 - 1e-12)
        dof = idx.size - Q.shape[1] - 1
        if dof < 3:
            break
        s2 = (float(e @ e) - e**2 / (1 - h)) / dof
        t = e / np.sqrt(np.maximum(s2, 1e-300) * (1 - h))
        j = int(np.argmax(np.abs(t)))
        if 2 * scipy.stats.t.sf(abs(t[j]), dof) * n >= alpha:
            break
        out.append((int(idx[j]), float(t[j])))
        alive[idx[j]] = False
    return out


def studentized(J: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Externally studentized residuals (n,) of r against design J."""
    Q = orthonormal(J)
    e = project_out(np.asarray(r, float)[:, None], Q)[:, 0]
    h = np.clip(np.sum(Q**2, axis=1), 0, 1 - 1e-12)
    dof = max(e.size - Q.shape[1] - 1, 1)
    s2 = (float(e @ e) - e**2 / (1 - h)) / dof
    return e / np.sqrt(np.maximum(s2, 1e-300) * (1 - h))


NEIGHBOUR_RADIUS_M = 0.025  # contacts this close on the same face see the same local face shape
NEIGHBOUR_T = 2.0


def has_like_neighbours(i: int, tip: np.ndarray, faces: np.ndarray, t: np.ndarray) -> bool:
    """Whether another contact on row i's face within NEIGHBOUR_RADIUS_M has a studentized
    residual of the same sign beyond NEIGHBOUR_T: a local structure (a dent, a bump on the face),
    located by the lack of fit, rather than one bad record."""
    near = (faces == faces[i]) & (np.linalg.norm(tip - tip[i], axis=1) < NEIGHBOUR_RADIUS_M)
    near[i] = False
    return bool(np.any(near & (np.sign(t) == np.sign(t[i])) & (np.abs(t) > NEIGHBOUR_T)))


def implausible_speed(speed_m_s: np.ndarray, limit: float = MAX_SEARCH_SPEED_M_S) -> np.ndarray:
    """Rows whose derived approach speed (m/s) is beyond what a touch search can be."""
    return np.flatnonzero(~np.isfinite(speed_m_s) | (np.asarray(speed_m_s, float) > limit))


SPEED_FACTOR = 2.0  # a derived approach speed this far from the commanded search speed is not that search


def speed_mismatch(derived_m_s: np.ndarray, commanded_m_s: np.ndarray, factor: float = SPEED_FACTOR) -> np.ndarray:
    """Rows whose derived approach speed is more than `factor` off the recorded commanded search
    speed (rows without a command, NaN, are not tested)."""
    d, c = np.asarray(derived_m_s, float), np.asarray(commanded_m_s, float)
    has = np.isfinite(c) & (c > 0)
    ratio = np.where(has, d / np.where(has, c, 1.0), 1.0)
    return np.flatnonzero(has & ~((ratio <= factor) & (ratio >= 1 / factor)))


def _p_without(y: np.ndarray, D: np.ndarray, S: np.ndarray, rows: np.ndarray) -> float:
    keep = np.ones(y.size, bool)
    keep[rows] = False
    return grouped_p(y[keep], D[keep], S[keep], int(keep.sum()))


CORROBORATION_ALPHA = 0.05  # a finding the rest of the records support at this level does not rest on one or two


def carried_by(y: np.ndarray, D: np.ndarray, S: np.ndarray, alpha: float, max_k: int = 2) -> list[int] | None:
    """The rows (≤ max_k) that carry the significance of columns S beside design D for data y:
    None when S stays significant at α (raw grouped F) with any one, or the `max_k` most
    influential, rows left out (influence = the p-value with that row alone left out)."""
    p1 = np.array([_p_without(y, D, S, np.array([i])) for i in range(y.size)])
    order = np.argsort(-p1, kind="stable")
    for k in range(1, max_k + 1):
        rows = order[:k]
        if _p_without(y, D, S, rows) > alpha:
            return [int(i) for i in rows]
    return None


def related(effect_variable: str, location: str, variables: list) -> list:
    """The lack-of-fit variables along an effect's own variable (`Effect.variable`)."""
    names = {"time": ("time_since_start_s",), "approach": ("approach_speed_m_s", "search_direction"),
             "face": (f"face {location} position",)}.get(effect_variable, (effect_variable,))
    return [v for v in variables
            if v.name in names or any(v.name.startswith(f"{nm}→") for nm in names)]


def misspecified(r: np.ndarray, A: np.ndarray, variables: list, alpha: float,
                 n_eff: int | None = None) -> tuple[float, str] | None:
    """(Bonferroni p, variable) when a flexible basis along any of `variables` adds significantly
    (grouped F) to the final design A for residual r: the effect named along that variable does
    not capture its form.  None when no variable is significant (or none is given)."""
    best = None
    for v in variables:
        p = min(1.0, grouped_p(r, A, v.columns, r.size if n_eff is None else n_eff) * len(variables))
        if best is None or p < best[0]:
            best = (p, v.name)
    return best if best is not None and best[0] < alpha else None


def linearised_subset(A: np.ndarray, r_final: np.ndarray, drop_cols: np.ndarray,
                      contributions: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(design, residual) of the final model without some findings, to first order: their
    columns removed and their fitted contributions put back into the residual."""
    keep = np.setdiff1d(np.arange(A.shape[1]), drop_cols)
    r = np.asarray(r_final, float).copy()
    for c in contributions:
        r = r - c.reshape(r.size)  # the augmented residual holds the effect term S·θ
    return A[:, keep], r


def advice_for(variable: str) -> str:
    """What to do about structure located along a lack-of-fit variable (no library term names it)."""
    if variable.startswith("face ") and variable.endswith(" position"):
        return (f"inspect {variable[5:-9]} (flatness, a dent or a bump: a surface plate and dial gauge), or touch it "
                "at more points spread over it")
    if variable.endswith("→growth"):
        return "log a temperature sensor near the links; revisit far-apart poses early and late (link growth)"
    if "→" in variable and variable.startswith("q_"):
        src, dst = variable[2:].split("→")
        return f"move {src} alone over its range with {dst} still, and the reverse: a coupling of {src} into {dst}"
    if variable.startswith("q_"):
        return f"sweep {variable[2:]} alone over its range in small steps (a localised transmission error)"
    if variable.startswith(("time", "temperature")):
        return "log a temperature sensor; interleave the faces in time; let the arm warm up before the campaign"
    if variable in ("approach_speed_m_s", "search_direction"):
        return "vary the search speed and direction on the same faces (touch-sensor behaviour)"
    if variable == "payload_kg":
        return "repeat the same points with each payload (a payload-dependent deflection)"
    return "add measurements that vary this variable alone"


def status(n_findings: int, located: bool, floor: dict | None, worse: bool,
           misfit: list[str] = (), design: dict | None = None) -> tuple[str, str]:
    """(status, reason) of a diagnosis (module docstring); `misfit`: the variables along which a
    named effect's form leaves structure (`misspecified`); `design`: the held-out RMS over the in-sample σ
    (`resampling.holdout_over_insample`) — flagged, the status is never `clean` or `explained`."""
    above = bool(floor and floor.get("above_floor"))
    far = bool(design and design.get("flagged"))
    if worse:
        return ("model_worse_out_of_sample", "modelling the selected effects made the cross-validated RMS worse than "
                "geometry alone: nothing is reported as found")
    left = " and ".join(w for w, b in (("structure located by the lack-of-fit test", located),
                                       ("residuals above the noise floor", above),
                                       (f"structure along {', '.join(misfit)} that the named form misses",
                                        bool(misfit)),
                                       (f"a held-out RMS {max(design['geometry'], design['final']):.1f}× the in-sample σ "
                                        "(the campaign cannot predict its own left-out measurements: the design, or "
                                        "an error the model lacks)" if far else "", far)) if b)
    if n_findings and left:
        return "partially_explained", f"findings explain part of the residual; left: {left}"
    if n_findings:
        return "explained", "findings bring the fit back to the noise floor" if floor else \
            "findings leave no located structure (no declared noise floor to compare with)"
    if left:
        return "unexplained", f"no library effect explains it; left: {left}"
    return "clean", "no finding, no located structure" + ("" if floor else " (no declared noise floor)")
