"""Which gravity-compliance families a shrinkage fit keeps, and how it estimates them.

The physics terms of a `TreePointModel` (``J.compliance``, ``J.lateral1/2``, rad/(N·m);
`pipeline.physics.compliance`) are estimated with the registration, against the nominal robot: the
instrument frame, the tool point and the compliances that explain how the error follows the gravity
load before any link is moved.  The geometry is then shrunk toward nominal with those terms anchored at
their registration-stage values (`pipeline.identify.shrinkage`, ``extra``), not pulled toward zero.
Where the evidence chooses the scales (no row groups), the joint compliance is also offered estimated with
the geometry (`stagings`): on a robot whose nominal geometry is far off (FIGAROH's TALOS arm: 3 mm before
calibration) a compliance estimated against it takes up the geometry's error and is then held there.

Each subset of the offered families (none, each alone, all) is a candidate; a candidate is
*admissible* only when every compliance it estimates is physical, i.e. not negative beyond
`NEGATIVE_SIGMA` of its standard error (a stiffness is positive: a negative compliance absorbs
something else).  The model-choice score is GCV counting the physics terms as estimated parameters, or
the held-out error of left-out groups — there each fold re-estimates the compliances from its training
groups, anchored at the all-groups registration-stage values, so the left-out group's rows weigh a little
on its own prediction.  The rigid model is kept when it scores least; otherwise the physics is named by the
one-standard-error rule (`simplest_within_noise`: the fewest physics parameters within the noise of the
least score), and a candidate estimated with the geometry is kept only if, refitted on folds of the fitted
rows, it predicts them better than the best candidate estimated with the registration (`fold_rms`).  A
model whose terms were asked for explicitly (``--physics joint-compliance``: ``forced``) keeps all of them.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

SUFFIXES = {"compliance": "joint-compliance", "lateral1": "lateral-compliance", "lateral2": "lateral-compliance"}
SECOND_ORDER = (".compliance_load",)  # not chosen here (held at 0 unless forced): a load-dependent compliance
# anchored at a registration-stage estimate is the nominal geometry's error again; the group selection offers it
NEGATIVE_SIGMA = 2.0
WITH_REGISTRATION, WITH_GEOMETRY = "with the registration", "with the geometry"
CHECK_FOLDS = 5  # folds over rows that verify a candidate estimated with the geometry (`fold_rms`)
ONE_SE = 1.0  # a larger physics model is kept only when it scores better by more than this many standard errors
GEOMETRY_FAMILIES = ("joint-compliance",)  # the families also offered estimated with the geometry (`stagings`)
REFUSALS = 3  # at most this many rounds of holding negative compliances at 0 (`shrink_physical`)


def families(model) -> dict[str, tuple[str, ...]]:
    """{family: its parameter names} of the model's physics terms (empty for a rigid model)."""
    out: dict[str, list[str]] = {}
    for n in model.parameter_names():
        fam = SUFFIXES.get(n.rsplit(".", 1)[-1]) if "." in n else None
        if fam is not None:
            out.setdefault(fam, []).append(n)
    return {f: tuple(v) for f, v in out.items()}


def candidates(model) -> list[tuple[str, ...]]:
    """Family subsets to try, the rigid model first; only the full set when the terms were forced."""
    fams = sorted(families(model))
    if not fams:
        return [()]
    if getattr(model, "forced", False):
        return [tuple(fams)]
    return [c for k in range(len(fams) + 1) for c in combinations(fams, k)]


def stagings(model, grouped: bool = False) -> list[tuple[tuple[str, ...], str]]:
    """(family subset, how its terms are estimated) of every candidate: each subset of `candidates` with its
    terms estimated with the registration (anchored there, `WITH_REGISTRATION`), and — where the evidence
    chooses each family's scale (no row groups: `grouped` False) — the joint compliance alone also estimated
    with the geometry (`WITH_GEOMETRY`: shrunk toward the rigid robot by its own family scale, as the
    specialists estimate joint elasticity together with the kinematic parameters).  On a robot whose nominal
    geometry is far off, a compliance estimated against it at the registration stage takes up the geometry's
    error and is then held there; estimated with the geometry it does not.  The lateral family is offered with
    the registration only (`GEOMETRY_FAMILIES`).  Forced terms: the subset of all, with the registration only."""
    out = [(c, WITH_REGISTRATION) for c in candidates(model)]
    if grouped or getattr(model, "forced", False):
        return out
    return out + [(c, WITH_GEOMETRY) for c in candidates(model) if c and set(c) <= set(GEOMETRY_FAMILIES)]


def label(chosen: tuple[str, ...], stage: str) -> str:
    """A candidate's name in `physics_families`: its families ("rigid" for none), "(with the geometry)" when so."""
    return ("+".join(chosen) or "rigid") + (f" ({stage})" if chosen and stage == WITH_GEOMETRY else "")


def shrink_physical(model, data, prior, x0, fixed: tuple[str, ...], on: tuple[str, ...], extra: tuple[str, ...],
                    progress=None):
    """(`evidence.shrink_evidence` of the candidate whose terms `on` are estimated, names held at 0, names still
    negative): a term that cannot be negative (``nonnegative``) estimated negative is held at 0 (`x0` has it
    there) and the rest estimated again, at most `REFUSALS` times, so the candidate scored is the physical one (a
    stiffness is positive; a negative compliance absorbs something else).  Names still negative after that make
    the candidate inadmissible."""
    from pipeline.identify.evidence import shrink_evidence

    hook = getattr(model, "nonnegative", None)
    allowed = sorted(set(hook()) & set(on)) if hook is not None and not getattr(model, "forced", False) else []
    names, refused = model.parameter_names(), ()
    s = shrink_evidence(model, data, prior, x0, fixed=fixed, progress=progress, extra=extra)
    for k in range(REFUSALS + 1):
        neg = tuple(n for n in allowed if n not in refused and s.x[names.index(n)] < 0)
        if not neg or k == REFUSALS:
            return s, refused, neg
        refused += neg
        s = shrink_evidence(model, data, prior, x0, fixed=fixed + refused, progress=progress, extra=extra)
    return s, refused, ()


def simplest_within_noise(scored: list[tuple[float, int, np.ndarray]], z: float = ONE_SE) -> int:
    """Index of the candidate kept among `scored` — (score m², parameters of its physics terms, per-row shares of
    the score (n,): their mean is the score), in the order the candidates were tried; the rigid model has none.

    Whether the robot bends at all is decided by the least score, as before: the rigid model is kept only when
    it scores least.  Which physics names it is decided by the one-standard-error rule of cross-validation
    (Breiman et al. 1984; Hastie, Tibshirani & Friedman §7.10): among the physics candidates whose score is
    within `z` standard errors of the least physics score (the standard error of that score's mean over rows),
    the one with fewest physics parameters (the first tried among equals) that scores below the rigid model.
    Two families that bend the robot
    about parallel axes (a joint's compliance, its parent's lateral compliance about the same direction)
    predict alike and the larger one fits a little more of the noise: the data do not name one over the
    other, and the smaller model is the one kept."""
    best = min(range(len(scored)), key=lambda i: scored[i][0])
    if scored[best][1] == 0:
        return best
    rigid = min((scored[i][0] for i in range(len(scored)) if scored[i][1] == 0), default=np.inf)
    physics = [i for i in range(len(scored)) if scored[i][1] > 0 and scored[i][0] < rigid]
    if not physics:  # a physics candidate tied with the rigid model: the rigid one is kept
        return min((i for i in range(len(scored)) if scored[i][1] == 0), key=lambda i: scored[i][0])
    rows = np.asarray(scored[best][2], float)
    se = float(np.std(rows, ddof=1) / np.sqrt(rows.size)) if rows.size > 1 else 0.0
    bar = scored[best][0] + z * se
    return min((i for i in physics if scored[i][0] <= bar), key=lambda i: (scored[i][1], i))


def names_of(model, chosen: tuple[str, ...]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(names of the chosen families' terms, names of the others: held at 0, the rigid nominal).  The
    reading-error terms (`pipeline.physics.encoder`) are among the others unless the model's terms were
    forced: the shrinkage route chooses only among the gravity-compliance families."""
    from pipeline.physics.encoder import is_encoder

    fams = families(model)
    on = tuple(n for f in chosen for n in fams[f])
    off = tuple(n for f, v in fams.items() if f not in chosen for n in v)
    if not getattr(model, "forced", False):  # reading errors are not chosen here: held at their nominal 0
        off += tuple(n for n in model.parameter_names() if is_encoder(n) or n.endswith(SECOND_ORDER))
    return on, off


def inadmissible(fit, names: tuple[str, ...], model=None) -> list[str]:
    """The terms of `names` whose registration-stage estimate is negative beyond `NEGATIVE_SIGMA` σ — of those
    the model says cannot be negative (``nonnegative``: a compliance; a load-dependent compliance may be)."""
    hook = getattr(model, "nonnegative", None)
    if hook is not None:
        allowed = set(hook())
        names = tuple(n for n in names if n in allowed)
    idx = {n: i for i, n in enumerate(fit.names)}
    std = np.asarray(fit.std, float) if fit.std is not None else np.zeros(len(fit.names))
    return [n for n in names if fit.x[idx[n]] < 0 and fit.x[idx[n]] < -NEGATIVE_SIGMA * std[idx[n]]]


def fold_rms(model, data, prior, x0, fixed: tuple[str, ...], on: tuple[str, ...], extra: tuple[str, ...],
             folds: list[np.ndarray]) -> float:
    """RMS (m) over every row of a candidate's error on rows it was not fitted on: for each of `folds` (row
    indices) the candidate estimated again on the other rows as `shrink_physical` estimates it (its scales by
    the evidence of those rows), its residuals on the fold.  What verifies a candidate estimated with the
    geometry before it is kept (`shrinkage_fit`): its GCV is that of the linearised model at the scales its own
    rows chose, and a few dozen rows can make the compliance look free of cost."""
    from pipeline.identify.model import take

    n = len(next(iter(data.values())))
    sq, count = 0.0, 0
    for test in folds:
        train = np.setdiff1d(np.arange(n), test)
        s, _, neg = shrink_physical(model, take(data, train), prior, x0, fixed, on, extra)
        r = np.asarray(model.residuals(s.x, take(data, test)), float)
        sq, count = sq + float(np.sum(r**2)), count + r.size
    return float(np.sqrt(sq / max(count, 1)))
