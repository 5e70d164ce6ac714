"""The outlier screen's first robust fit (validate's check ``outliers``): what its robust z stands on.

One soft-L1 solve over the parameters the rank test of `pipeline.identify.identifiability` frees at the
start — the columns identify's `fit` starts from, found by the same code — run to the solver's tolerances.
It leaves out what identify's full fit adds on top: the re-test of the rank at each solution (which frees
parameters identifiable only off the nominal geometry and restarts the solve) and the refusal of negative
compliances (another solve per round).  Those decide which *parameter values* are believed; a screen needs
only residuals at a minimum, and each extra round, capped, left the screen on an iterate short of one (the
TIAGo arm's 34 rows: 6 solves capped at 200 evaluations each, 8 s CPU, the screen on the last one's iterate).

The cap (`cap`, evaluations) stays as a bound, not the expected stop: a model whose forward kinematics is
itself iterative (the extended Delta's Newton) reaches its residuals' round-off long before trf's 1e-12
tolerances; `still_falling` tells that apart from a stop short of the minimum.
"""

from __future__ import annotations

from pipeline.identify.least_squares import Fit, FitOptions, fit

DEFAULT_CAP = 400  # evaluations: the TIAGo arm's 66 free parameters converge in ≈ 230


def first_fit(model, data: dict, f_scale: float, cap: int = DEFAULT_CAP) -> Fit:
    """The screen's fit of `model` to `data` (model columns): soft-L1 with scale `f_scale` (the model's
    residual unit: m, or px for a camera), over the parameters identifiable at the start, at most `cap`
    residual evaluations.  ``Fit.converged`` says whether it stopped at a tolerance."""
    return fit(model, data, FitOptions(loss="soft_l1", f_scale=f_scale, max_nfev=cap, retest=False,
                                       physical=False, before=False))


def still_falling(history: list[float], window: int = 20, rel: float = 1e-6) -> bool:
    """The fit's cost (RMS per evaluation) fell by more than `rel` over its last `window` evaluations
    (or it made fewer than 2·`window`): stopped by a cap before reaching its minimum, not only short of
    the solver's 1e-12 tolerances at round-off (the extended Delta's forward Newton)."""
    if len(history) < 2 * window:
        return True
    before, recent = min(history[:-window]), min(history[-window:])
    return before - recent > rel * max(recent, 1e-300)
