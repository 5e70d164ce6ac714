"""Shrinkage toward nominal with its scale and registration chosen by leaving out whole groups.

The candidates — μ = ∞ (registration only, the nominal robot), the grid of μ with the registration anchored at its
registration-only estimate, the half-steps either side of the best, and the registration free about it — are
scored on the problem linearised at one solved point, not each solved: each group's training fit is one
Gauss-Newton step from that point, with the candidate's penalty, on the other groups' rows
(`group_holdout.held_out_linear`; exact for a model linear in its parameters).  Only the
winner is solved; if the problem linearised at the winner prefers another candidate, that one is solved in turn
(at most `ROUNDS`).  Scores of solved candidates are exact (linearised at their own solution), the others
linearised; μ = ∞ is always solved (warm from the registration-only fit: the rule compares every group with it).
"""

from __future__ import annotations

import numpy as np

from pipeline.identify.group_holdout import held_out_linear, per_group_rms
from pipeline.identify.shrinkage import GRID, ROUNDS, Shrunk, _anchor, _implausible, _penalty, map_solve


def shrink_by_groups(model, data, prior_sigma: np.ndarray, x0: np.ndarray, groups: np.ndarray,
                     fixed: tuple[str, ...] = (), grid=GRID, progress=None, extra: tuple[str, ...] = ()) -> Shrunk:
    """MAP estimate with μ chosen by leaving out whole groups (`group_holdout`): the candidates are the
    grid and μ = ∞ (registration only, the nominal robot); a μ is eligible only if no left-out group is
    predicted worse than by registration only, and the eligible μ of least held-out RMS is chosen, then
    refined once by the same rule over the geometric midpoints either side of it (half a grid step).
    The registration is anchored at its registration-only estimate (`shrinkage._anchor`); the same rule then
    judges it free (unpenalised) at the chosen μ and its two midpoints, and keeps whichever predicts the left-out
    groups better: what carries over to a group the fit did not see decides, not an assumption.  Candidates are
    scored on the problem linearised at a solved one (module docstring): two or three solves in all."""
    nominal = np.asarray(model.nominal(), float)
    free, w = _penalty(model, np.asarray(prior_sigma, float), fixed, extra)
    weights = {True: w + _anchor(model, np.asarray(prior_sigma, float), fixed, extra), False: w}
    centre = np.where(w > 0, nominal, np.asarray(x0, float))
    idx = np.flatnonzero(free)
    reg = idx[w[idx] == 0]
    r0 = np.asarray(model.residuals(x0, data), float)
    scale = float(np.sqrt(np.mean(r0**2)))
    m = r0.size
    INF = (True, np.inf)
    solved: dict = {}  # key → (x, J (m, P), r (m,)) at its solution

    def cols_lam(key):
        anchored, mu = key
        return (reg, np.zeros(reg.size)) if np.isinf(mu) else (idx, mu * weights[anchored][idx])

    def solve(key, x):
        cols, lam = cols_lam(key)
        x = map_solve(model, data, x, cols, lam, nominal if np.isinf(key[1]) else centre)
        solved[key] = (x, np.asarray(model.jacobian(x, data), float).reshape(m, -1),
                       np.asarray(model.residuals(x, data), float).ravel())
        return key

    def judge_all(base):
        """(chosen key, {key: per-group RMS}, {key: total RMS}, {key: held-out residuals}, progress lines) of the
        staged choice, every candidate not solved scored on the problem linearised at the solved candidate `base`."""
        xb, J, r = solved[base]
        per, total, outs, lines = {}, {}, {}, []

        def judge(key, label):
            cols, lam = cols_lam(key)
            xk, Jk, rk = solved.get(key, (xb, J, r))  # exact (at its own solution), else at the base's
            h = held_out_linear(model, data, groups, xk, cols, lam, centre, J=Jk, r=rk)
            per[key], total[key], outs[key] = per_group_rms(h, groups), float(np.sqrt(np.nanmean(h**2))), h
            anchored, mu = key
            lines.append(f"model choice {label}: μ = {mu * 1e3:.4g} mm{'' if anchored else ', registration free'}, "
                         f"held-out (whole groups left out) RMS {total[key] * 1e3:.4g} mm"
                         + ("" if key in solved else " (linearised)"))

        def best(anchored=(True, False)):
            ok = [k for k in per if k[0] in anchored and all(per[k][g] <= per[INF][g] for g in per[INF])]
            return min(ok, key=lambda k: total[k])

        cands = [np.inf] + [g * scale for g in sorted(grid, reverse=True)]
        for i, mu in enumerate(cands):
            judge((True, mu), f"{i + 1}/{len(cands)}")
        key = best()
        if not np.isinf(key[1]) and len(grid) > 1:  # refine: the geometric midpoints either side of the grid point
            step = np.sqrt(max(grid) / min(grid)) ** (1 / max(len(grid) - 1, 1))
            for k, mu in enumerate((key[1] * step, key[1] / step)):
                judge((True, mu), f"refined {k + 1}/2")
            key = best()
            for k, mu in enumerate((key[1] * step, key[1], key[1] / step)):  # the registration free, about it
                judge((False, mu), f"registration free {k + 1}/3")
            key = best()
        return key, per, total, outs, lines

    solve(INF, np.asarray(x0, float).copy())
    base = solve((True, sorted(grid)[len(grid) // 2] * scale), solved[INF][0])
    for _ in range(ROUNDS + 1):
        key, per, total, outs, lines = judge_all(base)
        if key in solved:
            break
        base = solve(key, solved[base][0])  # warm from the point the choice was linearised at
    if key not in solved:  # rounds exhausted: the best of the solved candidates, each scored at its own solution
        ok = [k for k in solved if k in per and all(per[k][g] <= per[INF][g] for g in per[INF])]
        key = min(ok, key=lambda k: total[k])
    for line in lines if progress is not None else ():  # the last round's scores
        progress(line)
    if progress is not None:
        progress(f"model choice: {len(solved)} candidates solved, the others scored on the problem linearised at "
                 f"the last solved")
    anchored, mu = key
    cands = sorted((m_ for a, m_ in per if a == anchored or np.isinf(m_)), reverse=True)
    xb, Jb, _ = solved[key]
    J = Jb[:, idx]
    lam = (0.0 if np.isinf(mu) else mu) * weights[anchored][idx]
    dof = float(np.trace(np.linalg.pinv(J.T @ J + np.diag(lam**2), rcond=1e-12, hermitian=True) @ (J.T @ J)))
    at = lambda m_: INF if np.isinf(m_) else (anchored, m_)  # noqa: E731
    other = {float(m_): total[(a, m_)] ** 2 for a, m_ in per if a != anchored and not np.isinf(m_)}
    return Shrunk(xb, float(mu), {float(m_): total[at(m_)] ** 2 for m_ in cands}, dof,
                  [] if np.isinf(mu) else _implausible(model, xb, idx, w, nominal), len(solved),
                  per_group={float(m_): per[at(m_)] for m_ in cands}, holdout=outs[key],
                  registration="anchored" if anchored else "free", other_registration=other)
