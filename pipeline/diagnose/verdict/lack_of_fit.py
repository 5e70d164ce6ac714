"""Lack-of-fit: does structure remain in the residuals that no accepted term explains, and where?

For each variable v (each joint angle, time since start, approach speed) a smooth basis
— Gaussian bumps φ_m(v) at K centres over v's range, mapped into the residual the way an
error in that variable would act (a joint-angle error through the joint's Jacobian column, a
time-dependent error per jig axis, a speed-dependent error along the face normal) — is
projected against the current design A (free geometry + accepted effects) and tested with a
grouped F test; Holm's correction across variables at family α.  With pose clusters (the
scanner) the statistic is a scan instead: the largest single-bump F over centres × widths,
calibrated by the restricted wild cluster bootstrap of that max (`scan_cluster_p`), which has
the power against localised structure (a transmission bump acting on a few poses) that an
8-dof smooth F spreads thin.  `region` is the best narrow bump's interval (the scan's best
element, with clusters).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.stats

from pipeline.diagnose.inference.projection import orthonormal, project_out
from pipeline.diagnose.inference.sign_flips import wild_cluster_p
from pipeline.diagnose.verdict.bump_locate import locate
from pipeline.models import serial_arm
from pipeline.progress import step


@dataclass(frozen=True)
class Variable:
    """A candidate location of structure: name, unit, its values (n,), and the basis builder
    ``basis(values) -> (n, K·c)`` of residual columns plus a grid map for locating."""

    name: str
    unit: str
    values: np.ndarray
    columns: np.ndarray  # (n, kb) residual columns
    centres: np.ndarray  # (K,) centres of the bumps along v
    width: float
    gain: np.ndarray  # (n, c) how a unit error in v-space reaches each residual (c channels)
    categorical: bool = False
    # local alternatives to a whole-place term at `place` (a library term's location, e.g. a face): residual
    # columns (n, S) of narrow bumps, each at one point of the place (`grading.grade`: a dent, not a bowl)
    local: np.ndarray | None = None
    place: str = ""


def rbf(v: np.ndarray, centres: np.ndarray, width: float) -> np.ndarray:
    """Gaussian bumps (n, K)."""
    return np.exp(-0.5 * ((np.asarray(v, float)[:, None] - centres[None]) / width) ** 2)


def smooth_variable(name: str, unit: str, v: np.ndarray, gain: np.ndarray, K: int = 8) -> Variable | None:
    """Variable with K bumps over the range of v; `gain` (n, c): residual per unit error, per channel."""
    v = np.asarray(v, float)
    lo, hi = float(np.min(v)), float(np.max(v))
    if hi - lo <= 1e-12:
        return None
    centres = np.linspace(lo, hi, K)
    width = (hi - lo) / (K - 1)
    Phi = rbf(v, centres, width)
    cols = (gain[:, :, None] * Phi[:, None, :]).reshape(v.size, -1)
    return Variable(name, unit, v, cols, centres, width, gain)


def touch_variables(x: np.ndarray, table, joint_names: list[str], speed: np.ndarray | None) -> list[Variable]:
    """The variables of a touch campaign: each joint angle, time, the temperature rise (when
    recorded), approach speed.  (Per-face
    structure is the library's `face_offset`, tested against the jig's machining tolerance.)"""
    q = np.asarray(table["joint_positions"], float)
    ax = np.asarray(table["axis"], int)
    rows = np.arange(ax.size)
    _, Jq = serial_arm.joint_jacobian(x, q)
    out: list[Variable] = []
    for j, name in enumerate(joint_names):
        v = smooth_variable(f"q_{name}", "rad", q[:, j], Jq[rows, ax, j][:, None])
        if v is not None:
            out.append(v)
    onehot_axis = np.eye(3)[ax]
    v = smooth_variable("time_since_start_s", "s", table["time_since_start_s"], onehot_axis, K=6)
    if v is not None:
        out.append(v)
    if "temperature_rise_K" in table:  # a recorded temperature channel (diagnose.table); several sensors: each
        for col in ["temperature_rise_K"] + [k for k in table if k.startswith("temperature_rise_K@")]:
            v = smooth_variable(col, "K", table[col], onehot_axis, K=6)
            if v is not None:
                out.append(v)
    if speed is not None and np.ptp(speed) > 0.2 * np.max(np.abs(speed)):
        v = smooth_variable("approach_speed_m_s", "m/s", speed, np.asarray(table["normal_sign"], float)[:, None], K=4)
        if v is not None:
            out.append(v)
    return out


@dataclass
class LackOfFit:
    """Outcome for one variable."""

    variable: str
    statistic: float
    dof: tuple[int, int]
    p_value: float
    p_holm: float
    significant: bool
    region: tuple[float, float] | str
    peak_m: float  # largest fitted residual structure, m


SCAN_DIVISORS = (12, 6, 3)  # scan bump widths: the variable's range / each
N_SCAN = 25  # scan centres per width


@dataclass(frozen=True)
class Scan:
    """Single-bump alternatives along a variable: `U` (N, m) the orthonormal columns of every
    (centre, width) bump ⊥ the design, `group` (m,) which scan element each column belongs to,
    `kb` (S,) columns per element, `centres`, `widths` (S,) in v's unit."""

    U: np.ndarray
    group: np.ndarray
    kb: np.ndarray
    centres: np.ndarray
    widths: np.ndarray


def scan_basis(v: Variable, QA: np.ndarray, whiten=None, divisors: tuple[int, ...] = SCAN_DIVISORS,
               n_scan: int = N_SCAN) -> Scan | None:
    """Every single Gaussian bump along v (`n_scan` centres over the range × widths range/d),
    mapped through v's gain (and the whitener), each orthonormalised ⊥ the design QA."""
    lo, hi = float(v.centres[0]), float(v.centres[-1])
    cs = np.tile(np.linspace(lo, hi, n_scan), len(divisors))
    ws = np.repeat([(hi - lo) / d for d in divisors], n_scan)
    Phi = np.exp(-0.5 * ((v.values[:, None] - cs[None]) / ws[None]) ** 2)  # (n, S)
    c = v.gain.shape[1]
    cols = (v.gain[:, :, None] * Phi[:, None, :]).reshape(v.values.size, -1)  # column channel·S + s
    if whiten is not None:
        cols = whiten(cols)
    P = project_out(cols, QA)
    if c == 1:  # one column per element: normalise (a column the design absorbs is dropped)
        n0, n1 = np.linalg.norm(cols, axis=0), np.linalg.norm(P, axis=0)
        keep = n1 > 1e-6 * np.maximum(n0, 1e-300)
        if not keep.any():
            return None
        return Scan(P[:, keep] / n1[keep], np.flatnonzero(keep), keep.astype(int), cs, ws)
    Us, grp, kb = [], [], np.zeros(cs.size, int)
    for s in range(cs.size):
        B, B0 = P[:, s::cs.size], cols[:, s::cs.size]  # element s's c channel columns
        keep = np.linalg.norm(B, axis=0) > 1e-6 * np.maximum(np.linalg.norm(B0, axis=0), 1e-300)
        if not keep.any():
            continue
        Q = orthonormal(B[:, keep], 1e-6)
        Us.append(Q)
        grp.append(np.full(Q.shape[1], s))
        kb[s] = Q.shape[1]
    if not Us:
        return None
    return Scan(np.hstack(Us), np.concatenate(grp), kb, cs, ws)


def scan_gains(sc: Scan, R: np.ndarray) -> np.ndarray:
    """Sum of squares of residual column(s) R (N, B) each scan element explains: (S, B)."""
    G = (np.arange(sc.kb.size)[:, None] == sc.group[None]).astype(float)  # element × column
    return G @ (sc.U.T @ R) ** 2


def best_element(sc: Scan, r: np.ndarray) -> int:
    """The scan element explaining most of residual r (N,) per direction it adds."""
    g = scan_gains(sc, r[:, None])[:, 0] / np.maximum(sc.kb, 1)
    g[sc.kb == 0] = -np.inf
    return int(np.argmax(g))


def scan_statistic(sc: Scan, R: np.ndarray, rss: np.ndarray, dof: int) -> tuple[np.ndarray, np.ndarray]:
    """F of every scan element for residual column(s) R (N, B) with total RSS `rss` (B,):
    returns (max over the scan (B,), argmax (B,))."""
    F = _scan_F(sc, scan_gains(sc, R), rss, dof)
    return F.max(axis=0), F.argmax(axis=0)


def _scan_F(sc: Scan, g: np.ndarray, rss: np.ndarray, dof: int) -> np.ndarray:
    """F (S, B) of every scan element from its gains g (S, B) and the total RSS (B,)."""
    kb = np.maximum(sc.kb, 1)[:, None]
    F = (g / kb) / (np.maximum(rss[None] - g, 1e-300) / np.maximum(dof - kb, 1))
    F[sc.kb == 0] = -np.inf
    return F


@dataclass(frozen=True)
class ClusterFlips:
    """The restricted wild cluster bootstrap residuals R = P⊥(s[cluster] ⊙ r̂) (N, B) held by their
    cluster-level factors, never formed: the signs `S` (C, B), each row's cluster `inv` (N,), r̂ (N,)
    and the design's orthonormal basis QA (N, p).  Any Mᵀ R is then (cluster sums of M ⊙ r̂)ᵀ S minus
    MᵀQA (QAᵀ R), and |R_b|² = |r̂|² − |QAᵀ R_b|²: O(N·m + C·m·B) instead of O(N·B) memory and time
    (a camera's thousands of corners in a dozen images, 3 000 draws)."""

    S: np.ndarray
    inv: np.ndarray
    res: np.ndarray
    QA: np.ndarray

    @cached_property
    def _sum_r(self):
        """The sparse (C, N) matrix whose row c sums r̂ over cluster c's rows."""
        import scipy.sparse

        n = self.inv.size
        return scipy.sparse.csr_matrix((self.res, (self.inv, np.arange(n))), shape=(self.S.shape[0], n))

    def cluster_sums(self, M: np.ndarray) -> np.ndarray:
        """(C, m): per cluster, the sum over its rows of M ⊙ r̂."""
        return np.asarray(self._sum_r @ np.asarray(M, float))

    def project(self, M: np.ndarray) -> np.ndarray:
        """Mᵀ R (m, B)."""
        a = self.cluster_sums(M).T @ self.S
        return a - (M.T @ self.QA) @ self.qa_r

    @cached_property
    def qa_r(self) -> np.ndarray:
        return self.cluster_sums(self.QA).T @ self.S  # QAᵀ (s ⊙ r̂) (p, B)

    @cached_property
    def rss(self) -> np.ndarray:
        return float(self.res @ self.res) - np.sum(self.qa_r**2, axis=0)


def sign_flips(res: np.ndarray, QA: np.ndarray, cluster: np.ndarray, n_boot: int = 2999, seed: int = 0) -> ClusterFlips:
    """Restricted wild cluster bootstrap residuals (`ClusterFlips`, (N, n_boot) as factors): r̂ (⊥ design)
    with each cluster's rows times one random sign, re-projected ⊥ the design QA."""
    ids, inv = np.unique(cluster, return_inverse=True)
    rng = np.random.default_rng(seed)
    return ClusterFlips(rng.choice([-1.0, 1.0], (ids.size, n_boot)), inv.ravel(), np.asarray(res, float), QA)


def scan_cluster_p(sc: Scan, T: float, R, dof: int) -> float:
    """p-value of the scan statistic T (the largest single-bump F over the scan) by the restricted
    wild cluster bootstrap (`sign_flips` R, as `sign_flips.wild_cluster_p`): per replicate the max over the
    whole scan, so the multiplicity of the scan is in the reference distribution.  (The
    unrestricted pool — r̂ less its best bump — is no use here: a bump on one cluster is invariant
    to that cluster's sign, so the replicates would never reach T and clean data would be rejected.)
    R: (N, B) residual draws, or their `ClusterFlips` factors."""
    if isinstance(R, ClusterFlips):
        G = (np.arange(sc.kb.size)[:, None] == sc.group[None]).astype(float)
        Ts = _scan_F(sc, G @ R.project(sc.U) ** 2, R.rss, dof).max(axis=0)
        return float((1 + np.sum(Ts >= T)) / (1 + R.S.shape[1]))
    Ts, _ = scan_statistic(sc, R, np.sum(R**2, axis=0), dof)
    return float((1 + np.sum(Ts >= T)) / (1 + R.shape[1]))


def test(r: np.ndarray, A: np.ndarray, variables: list[Variable], dof_resid: int, alpha: float = 0.01,
         whiten=None, original: tuple | None = None, cluster: np.ndarray | None = None,
         seed: int = 0, scan: bool = True, draws: np.ndarray | None = None) -> list[LackOfFit]:
    """Grouped F test of each variable's smooth basis against design A, Holm across variables.
    With clustered errors, r, A and the variables' columns come whitened (`clustered.Whitener`),
    `whiten` is that W (for `locate`) and `original` = (r, A, variables) unwhitened: `peak_m`
    is then the smooth fitted to the original residuals (m, not whitened units).  With
    `cluster` (the cluster of each row) the p-values come from the wild cluster bootstrap
    instead of the F distribution, which would hold only if the whitening's between-cluster
    covariance (estimated from a few clusters) were exact: with `scan` (default) of the scan
    statistic (`scan_basis`, `scan_cluster_p`; `statistic` is then the best element's F and
    `region` its centre ± width), else of the smooth basis's F (`sign_flips.wild_cluster_p`).  `draws` (N, B):
    residuals drawn from a parametric null model (whitened like r, e.g. `clustered.PhysicalModel.draw`)
    replace the sign flips as the scan statistic's reference (a parametric bootstrap).  `region` and `peak_m`
    are those of the significant variables ("" and 0 for the others)."""
    QA = orthonormal(A)
    if original is not None:
        QA0 = orthonormal(original[1])
        res0 = project_out(np.asarray(original[0], float)[:, None], QA0)[:, 0]
        cols0 = {v.name: v.columns for v in original[2]}
    res = project_out(r[:, None], QA)[:, 0]
    rss = float(res @ res)
    raw = []
    for i, v in enumerate(variables):
        step(f"lack of fit: variable {i + 1} of {len(variables)} ({v.name})")
        Bp = project_out(v.columns, QA)
        Qb = orthonormal(Bp, 1e-6)
        kb = Qb.shape[1]
        gain = float(np.sum((Qb.T @ res) ** 2)) if kb else 0.0
        if kb == 0 or dof_resid - kb < 2 or rss - gain <= 1e-12 * rss:  # no residual left beside the basis: no test
            raw.append((v, np.nan, (0, 0), 1.0, None, None))
            continue
        F = (gain / kb) / ((rss - gain) / (dof_resid - kb))
        p = float(scipy.stats.f.sf(F, kb, dof_resid - kb))
        raw.append((v, F, (kb, dof_resid - kb), p, Bp, Qb))
    scans: dict[str, tuple[float, float]] = {}
    if cluster is not None and scan:
        R = sign_flips(res, QA, cluster, seed=seed) if draws is None else draws - QA @ (QA.T @ draws)
        for k, (v, *_rest) in enumerate(raw):
            sc = None if raw[k][4] is None else scan_basis(v, QA, whiten)
            if sc is None:
                continue
            T, sb = scan_statistic(sc, res[:, None], np.array([rss]), dof_resid)
            T, sb = float(T[0]), int(sb[0])
            kb = int(sc.kb[sb])
            p = scan_cluster_p(sc, T, R, dof_resid)
            lo, hi = float(v.centres[0]), float(v.centres[-1])
            scans[v.name] = (max(lo, float(sc.centres[sb] - sc.widths[sb])), min(hi, float(sc.centres[sb] + sc.widths[sb])))
            raw[k] = (v, T, (kb, dof_resid - kb), p, raw[k][4], raw[k][5])
    elif cluster is not None:
        ok = [i for i, t in enumerate(raw) if t[5] is not None]
        ps = dict(zip(ok, wild_cluster_p(res, QA, [raw[i][5] for i in ok], cluster, seed=seed)))
        raw = [(*t[:3], ps.get(i, 1.0), *t[4:]) for i, t in enumerate(raw)]
    m = len(raw)
    order = np.argsort([t[3] for t in raw])
    p_holm = np.ones(m)
    running = 0.0
    stop = False
    sig = np.zeros(m, bool)
    for rank, i in enumerate(order):
        running = max(running, min(1.0, raw[i][3] * (m - rank)))
        p_holm[i] = running
        if not stop and raw[i][3] <= alpha / (m - rank):
            sig[i] = True
        else:
            stop = True
    out = []
    for i, (v, F, dof, p, Bp, _) in enumerate(raw):
        region: tuple[float, float] | str = ""
        peak = 0.0
        if Bp is not None and sig[i]:  # where and how large: for the structure found (nothing reads the rest's)
            B0, r0 = (Bp, res) if original is None else (project_out(cols0[v.name], QA0), res0)
            coef, *_ = np.linalg.lstsq(B0, r0, rcond=None)
            peak = float(np.max(np.abs(B0 @ coef)))
            region = scans.get(v.name) or locate(v, QA, res, whiten=whiten)
        out.append(LackOfFit(v.name, float(F) if np.isfinite(F) else 0.0, dof, p, float(p_holm[i]), bool(sig[i]),
                             region, peak))
    return out


def located_columns(v: Variable, region: tuple[float, float] | list[float]) -> np.ndarray:
    """The residual columns (n, c) of one Gaussian bump along v filling `region` (centre its
    middle, width half its length): the located unexplained structure as a design column."""
    lo, hi = float(region[0]), float(region[1])
    w = max((hi - lo) / 2, 1e-12)
    return v.gain * rbf(v.values, np.array([(lo + hi) / 2]), w)


def grouped_p(y: np.ndarray, D: np.ndarray, S: np.ndarray, n_eff: int) -> float:
    """p-value (grouped F) of columns S added to design D for data y (rows already whitened)."""
    Q0 = orthonormal(D)
    Qs = orthonormal(project_out(S, Q0), 1e-6)
    k = Qs.shape[1]
    d2 = n_eff - Q0.shape[1] - k
    if k == 0 or d2 < 2:
        return 1.0
    y = project_out(y[:, None], Q0)[:, 0]
    g = float(np.sum((Qs.T @ y) ** 2))
    return float(scipy.stats.f.sf((g / k) / (max(float(y @ y) - g, 1e-300) / d2), k, d2))


def partial_p(r_wo: np.ndarray, A_rest: np.ndarray, S: np.ndarray, B: np.ndarray, whiten=None) -> tuple[float, float]:
    """(p of columns S given design [A_rest, B], p of B given [A_rest, S]) for residual r_wo (the
    residual without S's fitted contribution), grouped F; with `whiten` (a `clustered.Whitener`) on the
    whitened problem and its effective rows.  S is a likely proxy for B when the first is large
    (S adds nothing beyond B) and the second small (B adds something beyond S)."""
    if whiten is not None:
        r_wo, A_rest, S, B = whiten(r_wo[:, None])[:, 0], whiten(A_rest), whiten(S), whiten(B)
        n_eff = whiten.n_effective
    else:
        n_eff = r_wo.size
    return grouped_p(r_wo, np.hstack([A_rest, B]), S, n_eff), grouped_p(r_wo, np.hstack([A_rest, S]), B, n_eff)


def best_bump(v: Variable, r: np.ndarray, A: np.ndarray, whiten=None,
              divisors: tuple[int, ...] = (12, 6)) -> tuple[float, float] | None:
    """Region (centre ± width, v's unit) of the single narrow bump along v (widths range/d) that
    explains most of residual r beyond design A (on the whitened problem with `whiten`)."""
    if whiten is not None:
        r, A = whiten(r[:, None])[:, 0], whiten(A)
    QA = orthonormal(A)
    sc = scan_basis(v, QA, whiten, divisors)
    if sc is None:
        return None
    b = best_element(sc, project_out(r[:, None], QA)[:, 0])
    return float(sc.centres[b] - sc.widths[b]), float(sc.centres[b] + sc.widths[b])
