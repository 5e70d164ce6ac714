"""How much model the data support: parameter groups kept only when held-out error improves.

A model that offers ``groups()`` (name → parameter names; ``registration`` is always fitted)
is grown greedily (forward selection): starting from registration only, each round adds the
group whose k-fold cross-validated RMS is lowest, if it lowers it by at least `min_gain`
(relative) and the row-wise paired improvement is significant (one-sided, `z` standard errors);
it stops when no group does.  Small campaigns then try single parameters of the groups not kept
(screened by their linearised gain).  A model's ``late_groups()`` (optional: second-order terms such
as the errors of the joint readings) are offered only after that, against the model chosen without
them, so they never displace the groups offered first.  Thin data therefore keep registration only
rather than a model that wins the cross-validation by chance.  Each round's figures are kept so the result can
say which groups were kept and why.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pipeline.identify.least_squares import FitOptions, cross_validate, fit
from pipeline.identify.model import MeasurementModel, Table

MIN_GAIN = 0.02  # a group must lower the held-out RMS by 2 % to be kept
SINGLE_MAX_RESIDUALS = 200  # small campaigns: then try single parameters of the groups not kept
SINGLE_MAX_ROUNDS = 6
Z_KEEP = 1.645  # one-sided 95 %: the paired held-out improvement must exceed 1.645 standard errors
SINGLE_SCREEN = 5  # single parameters cross-validated per round: the best by linearised RSS reduction


@dataclass(frozen=True)
class Selection:
    kept: list[str]  # group names kept (registration first), then single parameters kept
    fixed: tuple[str, ...]  # parameter names held at their start values
    rounds: list[dict]  # [{"candidate": group, "holdout_rms_m": …, "kept": bool}, …]
    holdout_registration_m: float
    holdout_rms_m: float
    x: np.ndarray | None = None  # the kept model's solution where the choice solved it (closed form), else None


def _rms(r: np.ndarray) -> float:
    return float(np.sqrt(np.nanmean(r**2)))


def fixed_for(model: MeasurementModel, kept: list[str]) -> tuple[str, ...]:
    """Grouped parameters to hold fixed when `kept` (group names or single parameter names) are fitted."""
    groups = model.groups()
    free = {n for g in kept for n in groups.get(g, [g])}
    grouped = {n for v in groups.values() for n in v}
    return tuple(n for n in model.parameter_names() if n in grouped and n not in free)


def select(model: MeasurementModel, data: Table, k: int = 5, seed: int = 0, options: FitOptions = FitOptions(),
           min_gain: float = MIN_GAIN, groups_of_rows: np.ndarray | None = None, z: float = Z_KEEP,
           progress=None, closed_form: bool = False) -> Selection:
    """Forward selection of parameter groups by k-fold held-out error (see module docstring).

    A candidate is kept when it lowers the held-out RMS by `min_gain` AND the row-wise paired
    improvement of the squared held-out errors is significant: its mean exceeds `z` standard
    errors (one-sided).  On a few dozen rows a group can win the cross-validation by chance; the
    paired test asks that the win be carried by the rows, not by one or two of them.

    `closed_form` (k-fold only, not whole groups left out): each round's candidates are scored on the problem
    linearised at the solution of the model they extend, the folds in closed form (`linear_folds.Linearised`),
    and only the round's best are solved and rescored at their own solution — a fit per candidate chosen
    instead of a fit per fold of every candidate (a whole robot's few hundred parameters, 20 candidates)."""
    from pipeline.identify.group_holdout import held_out, row_groups

    late = [g for g in (getattr(model, "late_groups", lambda: ())()) if g in model.groups()]
    candidates = [g for g in model.groups() if g != "registration" and not g.startswith("_") and g not in late]
    kept = ["registration"]
    # sessions, placements, sockets: leave whole ones out, their own points / frames refitted from their rows
    whole = row_groups(model, data) if groups_of_rows is None else None

    def options_for(groups: list[str]) -> FitOptions:
        # candidates scored without refusing negative compliances (a refit per fold); the model kept is refitted
        # with the refusal and its held-out error measured so (`pipeline.stages.identify`)
        return replace(options, fixed=tuple(set(options.fixed) | set(fixed_for(model, groups))), physical=False)

    lin = None
    if closed_form and whole is None:
        from pipeline.identify.folds import design_folds
        from pipeline.identify.linear_folds import Linearised

        lin = Linearised(model, data, design_folds(len(next(iter(data.values()))), k, seed, groups_of_rows, data),
                         options_for)

    def errors(groups: list[str], base: list[str] | None = None, which: str = "") -> np.ndarray:
        opts = options_for(groups)
        head = f"model choice{which}: {' + '.join(groups)}"
        if lin is not None:  # scored on the problem linearised at `base`'s solution (or solved: registration)
            if base is None:
                lin.solve(groups)
            if progress is not None:
                progress(f"{head}, {k}-fold in closed form"
                         + (f", linearised at {' + '.join(base)}" if base is not None else ""))
            return lin.errors(groups, base or groups)
        if whole is not None:
            if progress is not None:
                progress(f"{head}, {len(np.unique(whole))} groups left out in turn")
            r = held_out(model, data, whole, lambda d, _: fit(model, d, replace(opts, before=False)).x, None)
        else:
            if progress is not None:
                progress(f"{head}, {k}-fold")
            r = cross_validate(model, data, k=k, seed=seed, options=opts, groups=groups_of_rows)
        return np.nansum(r**2, axis=1)  # squared held-out error per row

    def rms(e: np.ndarray) -> float:
        return float(np.sqrt(np.mean(e) / model.residual_dim))

    def better(e_new: np.ndarray, e_old: np.ndarray) -> tuple[bool, str]:
        """(kept, why): the three tests in turn, the first that fails named."""
        d = e_old - e_new
        se = float(np.std(d, ddof=1) / np.sqrt(d.size)) if d.size > 1 else np.inf
        gain = 1 - rms(e_new) / rms(e_old) if rms(e_old) > 0 else 0.0
        if gain < min_gain:
            return False, (f"held-out RMS {'raised' if gain < 0 else 'lowered'} by {abs(gain) * 100:.1f} % "
                           f"({min_gain * 100:.0f} % required)")
        if not float(d.mean()) > z * se:
            return False, (f"its gain is not carried by the rows (paired improvement {float(d.mean()) / se:.2f} "
                           f"standard errors, {z} required)")
        if whole is not None:  # never worse than registration only on a group it did not see
            worse = [str(g) for g in np.unique(whole) if e_new[whole == g].mean() > e_reg[whole == g].mean()]
            if worse:
                return False, f"predicts left-out group {', '.join(worse)} worse than registration only"
        return True, f"lowered the held-out RMS by {gain * 100:.1f} %"

    e_best = e_reg = errors(kept)
    reg = rms(e_best)
    rounds: list[dict] = [{"candidate": "registration", "holdout_rms_m": reg, "kept": True}]

    def grow(pool: list[str], label=lambda c: c) -> str | None:
        nonlocal e_best
        trial = {c: errors(kept + [c], list(kept) if lin is not None else None, f" (candidate {i} of {len(pool)})")
                 for i, c in enumerate(pool, 1)}
        if lin is not None:  # the best solved and rescored at their own solution; the others stay linearised
            c, exact = lin.settle(trial, kept, rms)
            if progress is not None:
                progress(f"model choice: {len(exact)} of {len(trial)} candidates solved ({', '.join(sorted(exact))})")
        else:
            c, exact = min(trial, key=lambda c: rms(trial[c])), set(trial)
        ok = better(trial[c], e_best)[0]
        for c2, e in trial.items():
            rounds.append({"candidate": label(c2), "holdout_rms_m": rms(e), "kept": bool(ok and c2 == c),
                           "against_m": rms(e_best),
                           "why": better(e, e_best)[1] if c2 == c or not ok else "another candidate lowered it more",
                           **({} if c2 in exact else {"linearised": True})})
        if not ok:
            return None
        kept.append(c)
        e_best = trial[c]
        return c

    while candidates and (g := grow(candidates)) is not None:
        candidates.remove(g)
    # a small campaign may support a few parameters of a group but not the whole group
    n_res = len(next(iter(data.values()))) * model.residual_dim
    # (not with whole groups left out: a few groups cannot judge single parameters, and each costs a fit per group)
    singles = ([n for g in candidates for n in model.groups()[g]] if n_res <= SINGLE_MAX_RESIDUALS and whole is None
               else [])
    for _ in range(SINGLE_MAX_ROUNDS if singles else 0):
        n = grow(_screen(model, data, kept, singles, options))
        if n is None:
            break
        singles.remove(n)
    while late and (g := grow(late)) is not None:  # second-order groups, against the model chosen without them
        late.remove(g)
    solved = lin.solved.get(tuple(kept)) if lin is not None else None
    return Selection(kept=kept, fixed=fixed_for(model, kept), rounds=rounds, holdout_registration_m=reg,
                     holdout_rms_m=rms(e_best), x=None if solved is None else solved[0])


def _screen(model: MeasurementModel, data: Table, kept: list[str], singles: list[str],
            options: FitOptions) -> list[str]:
    """The `SINGLE_SCREEN` candidates whose Jacobian column, projected off the fitted ones, would
    lower the residual sum of squares most in one linearised step (cheap: one fit)."""
    names = model.parameter_names()
    opts = replace(options, fixed=tuple(set(options.fixed) | set(fixed_for(model, kept))), before=False)
    f = fit(model, data, opts)
    r = f.residuals_after.ravel()
    J = model.jacobian(f.x, data).reshape(r.size, -1)
    Q, _ = np.linalg.qr(J[:, f.free]) if f.free.any() else (np.zeros((r.size, 0)), None)
    gain = {}
    for n in singles:
        j = J[:, names.index(n)]
        jp = j - Q @ (Q.T @ j)
        nn = float(jp @ jp)
        gain[n] = (float(jp @ r) ** 2 / nn) if nn > 1e-24 * max(float(j @ j), 1e-300) else 0.0
    return sorted(singles, key=lambda n: -gain[n])[:SINGLE_SCREEN]


def explain(sel: Selection, unit: str = "m") -> list[str]:
    """One line per decision, in mm (residuals in m) or px (a camera's, `unit` px)."""
    k, u = (1.0, "px") if unit == "px" else (1e3, "mm")
    lines = [f"registration only: held-out RMS {sel.holdout_registration_m * k:.3f} {u}"]
    for r in sel.rounds[1:]:
        verdict = "kept" if r["kept"] else "not kept"
        lines.append(f"+ {r['candidate']}: held-out {r['holdout_rms_m'] * k:.3f} {u}"
                     + (" (linearised)" if r.get("linearised") else "") + f" against "
                     f"{r['against_m'] * k:.3f} {u} → {verdict}" + (f" ({r['why']})" if r.get("why") else ""))
    return lines


def relabel(fit, sel: Selection) -> None:
    """Name the reason of the parameters the selection held fixed (instead of "fixed by the user")."""
    names = fit.names
    why = "not fitted: its group did not lower the held-out error (model_selection)"
    for n in sel.fixed:
        i = names.index(n)
        if fit.identifiability.reasons.get(i) == "fixed by the user":
            fit.identifiability.reasons[i] = why
