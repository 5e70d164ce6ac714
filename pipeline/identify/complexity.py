"""How much model the data support: parameter groups kept only when held-out error improves.

A model that offers ``groups()`` (name → parameter names; ``registration`` is always fitted)
is grown greedily (forward selection): starting from registration only, each round adds the
group whose k-fold cross-validated RMS is lowest, and stops when no group lowers it by at least
`min_gain` (relative).  Fewer data therefore never give a calibration worse out of sample than
registration alone — the selection would keep registration only.  Each round's figures are kept
so the result can say which groups were kept and why.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pipeline.identify.least_squares import FitOptions, cross_validate
from pipeline.identify.model import MeasurementModel, Table

MIN_GAIN = 0.02  # a group must lower the held-out RMS by 2 % to be kept
SINGLE_MAX_RESIDUALS = 200  # small campaigns: then try single parameters of the groups not kept
SINGLE_MAX_ROUNDS = 6
SINGLE_SCREEN = 5  # single parameters cross-validated per round: the best by linearised RSS reduction


@dataclass(frozen=True)
class Selection:
    kept: list[str]  # group names kept (registration first), then single parameters kept
    fixed: tuple[str, ...]  # parameter names held at their start values
    rounds: list[dict]  # [{"candidate": group, "holdout_rms_m": …, "kept": bool}, …]
    holdout_registration_m: float
    holdout_rms_m: float


def _rms(r: np.ndarray) -> float:
    return float(np.sqrt(np.nanmean(r**2)))


def fixed_for(model: MeasurementModel, kept: list[str]) -> tuple[str, ...]:
    """Grouped parameters to hold fixed when `kept` (group names or single parameter names) are fitted."""
    groups = model.groups()
    free = {n for g in kept for n in groups.get(g, [g])}
    grouped = {n for v in groups.values() for n in v}
    return tuple(n for n in model.parameter_names() if n in grouped and n not in free)


def select(model: MeasurementModel, data: Table, k: int = 5, seed: int = 0, options: FitOptions = FitOptions(),
           min_gain: float = MIN_GAIN, groups_of_rows: np.ndarray | None = None) -> Selection:
    """Forward selection of parameter groups by k-fold held-out RMS (see module docstring)."""
    candidates = [g for g in model.groups() if g != "registration" and not g.startswith("_")]
    kept = ["registration"]

    def score(groups: list[str]) -> float:
        opts = replace(options, fixed=tuple(set(options.fixed) | set(fixed_for(model, groups))))
        return _rms(cross_validate(model, data, k=k, seed=seed, options=opts, groups=groups_of_rows))

    best = score(kept)
    reg = best
    rounds: list[dict] = [{"candidate": "registration", "holdout_rms_m": best, "kept": True}]
    while candidates:
        trial = {g: score(kept + [g]) for g in candidates}
        g = min(trial, key=trial.get)
        ok = trial[g] < best * (1 - min_gain)
        for c, s in trial.items():
            rounds.append({"candidate": c, "holdout_rms_m": s, "kept": bool(ok and c == g),
                           "against_m": best})
        if not ok:
            break
        kept.append(g)
        candidates.remove(g)
        best = trial[g]
    # a small campaign may support a few parameters of a group but not the whole group
    n_res = len(next(iter(data.values()))) * model.residual_dim
    singles = [n for g in candidates for n in model.groups()[g]] if n_res <= SINGLE_MAX_RESIDUALS else []
    for _ in range(SINGLE_MAX_ROUNDS if singles else 0):
        trial = {n: score(kept + [n]) for n in _screen(model, data, kept, singles, options)}
        n = min(trial, key=trial.get)
        if not trial[n] < best * (1 - min_gain):
            rounds.append({"candidate": f"best single parameter {n}", "holdout_rms_m": trial[n], "kept": False,
                           "against_m": best})
            break
        rounds.append({"candidate": n, "holdout_rms_m": trial[n], "kept": True, "against_m": best})
        kept.append(n)
        singles.remove(n)
        best = trial[n]
    return Selection(kept=kept, fixed=fixed_for(model, kept), rounds=rounds, holdout_registration_m=reg,
                     holdout_rms_m=best)


def _screen(model: MeasurementModel, data: Table, kept: list[str], singles: list[str],
            options: FitOptions) -> list[str]:
    """The `SINGLE_SCREEN` candidates whose Jacobian column, projected off the fitted ones, would
    lower the residual sum of squares most in one linearised step (cheap: one fit)."""
    from pipeline.identify.least_squares import fit

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


def explain(sel: Selection) -> list[str]:
    """One line per decision, in mm."""
    lines = [f"registration only: held-out RMS {sel.holdout_registration_m * 1e3:.3f} mm"]
    for r in sel.rounds[1:]:
        verdict = "kept" if r["kept"] else "not kept"
        lines.append(f"+ {r['candidate']}: held-out {r['holdout_rms_m'] * 1e3:.3f} mm against "
                     f"{r['against_m'] * 1e3:.3f} mm → {verdict}")
    return lines


def relabel(fit, sel: Selection) -> None:
    """Name the reason of the parameters the selection held fixed (instead of "fixed by the user")."""
    names = fit.names
    why = "not fitted: its group did not lower the held-out error (model_selection)"
    for n in sel.fixed:
        i = names.index(n)
        if fit.identifiability.reasons.get(i) == "fixed by the user":
            fit.identifiability.reasons[i] = why
