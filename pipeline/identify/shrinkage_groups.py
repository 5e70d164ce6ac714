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
from pipeline.identify.plausibility import PLAUSIBLE
from pipeline.identify.shrinkage import GRID, ROUNDS, Shrunk, _anchor, _implausible, _penalty, map_solve


def shrink_by_groups(model, data, prior_sigma: np.ndarray, x0: np.ndarray, groups: np.ndarray,
                     fixed: tuple[str, ...] = (), grid=GRID, progress=None, extra: tuple[str, ...] = (),
                     tool: tuple[str, ...] = ()) -> Shrunk:
    """MAP estimate with μ chosen by leaving out whole groups (`group_holdout`): the candidates are the
    grid and μ = ∞ (registration only, the nominal robot); a μ is eligible only if no left-out group is
    predicted worse than by registration only, and the eligible μ of least held-out RMS is chosen, then
    refined once by the same rule over the geometric midpoints either side of it (half a grid step).
    The registration is anchored at its registration-only estimate (`shrinkage._anchor`); the same rule then
    judges it free (unpenalised) at the chosen μ and its two midpoints, and keeps whichever predicts the left-out
    groups better: what carries over to a group the fit did not see decides, not an assumption.  Candidates are
    scored on the problem linearised at a solved one (module docstring): two or three solves in all.

    `tool`: names of a tool point held known (at `x0`, its nominal) that the same rule may free (`_free_tool`):
    a ball centre off its drawing carries over to every placement, so the left-out groups see it."""
    nominal = np.asarray(model.nominal(), float)
    free, w = _penalty(model, np.asarray(prior_sigma, float), fixed, extra)
    weights = {True: w + _anchor(model, np.asarray(prior_sigma, float), fixed, extra), False: w}
    anchorable = bool(np.any(weights[True] != weights[False]))
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
            if anchorable:  # the registration free, about it (else anchored and free are one candidate)
                for k, mu in enumerate((key[1] * step, key[1], key[1] / step)):
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
    if np.isinf(key[1]):  # the nominal robot kept: never on a linearised score — solve what scored better, re-judge
        for k in sorted((k for k in per if total[k] < total[INF] and k not in solved), key=total.get)[:ROUNDS]:
            solve(k, solved[base][0])
            (xk, Jk, rk), (cols, lam) = solved[k], cols_lam(k)
            h = held_out_linear(model, data, groups, xk, cols, lam, centre, J=Jk, r=rk)
            per[k], total[k], outs[k] = per_group_rms(h, groups), float(np.sqrt(np.nanmean(h**2))), h
            if progress is not None:
                progress(f"model choice: μ = {k[1] * 1e3:.4g} mm{'' if k[0] else ', registration free'} solved "
                         f"(it scored below registration only): held-out RMS {total[k] * 1e3:.4g} mm")
        ok = [k for k in solved if k in per and all(per[k][g] <= per[INF][g] for g in per[INF])]
        key = min(ok, key=lambda k: total[k])
    passed = rejected_candidates(per, total, key, INF, solved)
    ref, beat = per[INF], total[key]
    tk = _free_tool(model, data, groups, prior_sigma, tool, idx, reg, weights, centre, nominal, solved[key],
                    solved[INF], sorted({m_ for _, m_ in per}, reverse=True), ref, beat) if tool else None
    fits = len(solved) + (len(tk["solved"]) if tk else 0)
    for line in lines if progress is not None else ():  # the last round's scores
        progress(line)
    for line in (tk["lines"] if tk else ()) if progress is not None else ():
        progress(line)
    if progress is not None:
        progress(f"model choice: {fits} candidates solved, the others scored on the problem linearised at "
                 f"the last solved")
    tool_state, other_tool = "", {}
    if tk:
        free_tool = tk["key"] is not None
        tool_state = "free" if free_tool else "known"
        if progress is not None:
            best_free = tk["best_free"]
            progress(f"model choice: the tool point {tool_state} ({', '.join(tool)}): held-out (whole groups left "
                     f"out) RMS {(tk['total'][tk['key']] if free_tool else beat) * 1e3:.4g} mm against "
                     f"{(beat if free_tool else best_free) * 1e3:.4g} mm with it "
                     f"{'known' if free_tool else 'free (its best plausible candidate)'}")
        if free_tool:
            other_tool = {float(m_): total[(key[0], m_) if not np.isinf(m_) else INF] ** 2
                          for a, m_ in per if a == key[0] or np.isinf(m_)}
            known_inf = per[INF], total[INF], outs[INF]
            key, per, total, outs, solved = tk["key"], tk["per"], tk["total"], tk["outs"], tk["solved"]
            idx, weights = tk["idx"], tk["weights"]
            if key != INF:  # "registration only" stays the reference the rule compares with: the tool known
                per[INF], total[INF], outs[INF] = known_inf
        else:
            other_tool = {float(m_): v ** 2 for (a, m_), v in tk["total"].items() if a == key[0] or np.isinf(m_)}
    anchored, mu = key
    cands = sorted((m_ for a, m_ in per if a == anchored or np.isinf(m_)), reverse=True)
    xb, Jb, _ = solved[key]
    J = Jb[:, idx]
    lam = (0.0 if np.isinf(mu) else mu) * weights[anchored][idx]
    dof = float(np.trace(np.linalg.pinv(J.T @ J + np.diag(lam**2), rcond=1e-12, hermitian=True) @ (J.T @ J)))
    at = lambda m_: INF if np.isinf(m_) else (anchored, m_)  # noqa: E731
    other = {float(m_): total[(a, m_)] ** 2 for a, m_ in per if a != anchored and not np.isinf(m_)}
    return Shrunk(xb, float(mu), {float(m_): total[at(m_)] ** 2 for m_ in cands}, dof,
                  [] if np.isinf(mu) else _implausible(model, xb, idx, w, nominal), fits,
                  per_group={float(m_): per[at(m_)] for m_ in cands}, holdout=outs[key],
                  registration="anchored" if anchored and anchorable else "free", other_registration=other,
                  tool=tool_state, other_tool=other_tool, passed_over=passed)


def rejected_candidates(per: dict, total: dict, key, ref, solved) -> list[dict]:
    """The candidates whose held-out RMS is below the chosen one's but were not chosen, each with why: the
    left-out groups it predicts worse than registration only (`ref`, the nominal robot) does — the rule of
    `shrink_by_groups` — and whether its score is its own solution's or linearised."""
    out = []
    for k in sorted((k for k in per if k != key and total[k] < total[key]), key=total.get):
        worse = {g: [per[k][g], per[ref][g]] for g in per[ref] if per[k][g] > per[ref][g]}
        out.append({"mu_m": None if np.isinf(k[1]) else float(k[1]),
                    "registration": "anchored" if k[0] else "free", "holdout_rms_m": float(total[k]),
                    "solved": k in solved, "worse_groups_m": worse,
                    "reason": ("predicts " + ", ".join(f"{g} worse ({a * 1e3:.4g} mm against {b * 1e3:.4g} mm with "
                                                        f"registration only)" for g, (a, b) in worse.items())
                               if worse else "not eligible")})
    return out


def _free_tool(model, data, groups, prior_sigma, tool, idx, reg, weights, centre, nominal, known, nominal_robot, mus,
               ref, beat):
    """The tool point freed, judged by the rule of `shrink_by_groups`: registration only with the tool freed
    (the nominal robot) and every μ of the tool-known choice, the registration anchored (the tool then pulled
    toward its nominal by its prior σ) and free, scored on the problem linearised at the tool-known winner
    `known` (x, J, r) — registration only at `nominal_robot` (x, J, r: the registration-only fit, the robot
    nominal), as only the registration and the tool move from there; a candidate is eligible only if it predicts
    no left-out group worse than registration only with the tool known (`ref`: group → RMS m), and it is taken only if its held-out RMS is below `beat`
    (the tool-known winner's) — for a model whose tool is estimated by default (a ball's centre:
    ``tool_estimated_by_default``) being eligible is enough — and only if its tool point stays within `PLAUSIBLE` prior σ of nominal (a free
    tool point can collapse onto a point no joint moves: far off, every socket fitted).  The best is solved and the scores linearised again there (at most `ROUNDS`),
    so the one taken is scored at its own solution.  Returns {key: (anchored, μ) or None (the tool stays
    known), per, total, outs, solved, idx, weights, lines}."""
    names = model.parameter_names()
    by_default = bool(getattr(model, "tool_estimated_by_default", False))  # eligible is enough (a ball's centre)
    tc = np.array([names.index(t) for t in tool], int)
    idx_t, reg_t = np.union1d(idx, tc), np.union1d(reg, tc)
    anchor = np.zeros(nominal.size)
    anchor[tc] = 1.0 / np.maximum(np.asarray(prior_sigma, float)[tc], 1e-12)
    w_t = {True: weights[True] + anchor, False: weights[False]}
    m = known[2].size
    keys = [(True, np.inf)] + [(a, m_) for a in (True, False) for m_ in mus if not np.isinf(m_)]
    solved: dict = {}

    def cols_lam(k):
        return (reg_t, np.zeros(reg_t.size)) if np.isinf(k[1]) else (idx_t, k[1] * w_t[k[0]][idx_t])

    sigma_t = np.asarray(prior_sigma, float)[tc]
    beyond = set()  # candidates whose solved tool point left its prior (`PLAUSIBLE` σ): collapsed, not eligible

    def tool_at(k, xk, Jk, rk):
        """The tool point (m) of candidate k: solved, or one Gauss-Newton step of the whole-data fit from xk."""
        if k in solved:
            return xk[tc]
        cols, lam = cols_lam(k)
        A = Jk[:, cols].T @ Jk[:, cols] + np.diag(lam**2)
        step = np.linalg.pinv(A, rcond=1e-12, hermitian=True) @ (Jk[:, cols].T @ rk + lam**2 * (xk[cols] - centre[cols]))
        x = xk.copy()
        x[cols] -= step
        return x[tc]

    def plausible(t):
        return bool(np.all(np.abs(t - nominal[tc]) <= PLAUSIBLE * sigma_t))

    base = known
    for _ in range(ROUNDS + 1):
        per, total, outs, tools = {}, {}, {}, {}
        for k in keys:
            cols, lam = cols_lam(k)
            xk, Jk, rk = solved.get(k, nominal_robot if np.isinf(k[1]) else base)
            h = held_out_linear(model, data, groups, xk, cols, lam, centre, J=Jk, r=rk)
            per[k], total[k], outs[k] = per_group_rms(h, groups), float(np.sqrt(np.nanmean(h**2))), h
            tools[k] = tool_at(k, xk, Jk, rk)
        ok = [k for k in keys if k not in beyond and plausible(tools[k]) and all(per[k][g] <= ref[g] for g in ref)]
        best = min(ok, key=total.get, default=None)
        if best is None or (total[best] >= beat and not by_default) or best in solved:
            break
        cols, lam = cols_lam(best)
        start = nominal_robot if np.isinf(best[1]) else base
        x = map_solve(model, data, start[0], cols, lam, nominal if np.isinf(best[1]) else centre)
        solved[best] = (x, np.asarray(model.jacobian(x, data), float).reshape(m, -1),
                        np.asarray(model.residuals(x, data), float).ravel())
        if not plausible(x[tc]):
            beyond.add(best)
        elif not np.isinf(best[1]):  # the robot moves only at a finite μ
            base = solved[best]
    ok = [k for k in solved if k not in beyond and all(per[k][g] <= ref[g] for g in ref)]  # at their own solutions
    win = min(ok, key=total.get, default=None)
    lines = ["model choice tool point free: " + ("registration only" if np.isinf(mu) else
             f"μ = {mu * 1e3:.4g} mm{'' if a else ', registration free'}")
             + f", held-out (whole groups left out) RMS {total[(a, mu)] * 1e3:.4g} mm"
             + ("" if (a, mu) in solved else " (linearised)")
             + ("" if (a, mu) not in beyond and plausible(tools[(a, mu)]) else
                f", tool point {np.max(np.abs(tools[(a, mu)] - nominal[tc])) * 1e3:.4g} mm off nominal: beyond its "
                f"prior, not eligible") for a, mu in keys]
    fair = [total[k] for k in keys if k not in beyond and plausible(tools[k])]
    return {"key": win if win is not None and (total[win] < beat or by_default) else None, "per": per, "total": total,
            "best_free": min(fair, default=float("nan")),
            "outs": outs, "solved": solved, "idx": idx_t, "weights": w_t, "lines": lines}
