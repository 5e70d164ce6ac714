"""Which gravity-compliance families a shrinkage fit keeps, and how it estimates them.

The physics terms of a `TreePointModel` (``J.compliance``, ``J.lateral1/2``, rad/(N·m);
`pipeline.physics.compliance`) are estimated with the registration, against the nominal robot: the
instrument frame, the tool point and the compliances that explain how the error follows the gravity
load before any link is moved.  The geometry is then shrunk toward nominal with those terms anchored at
their registration-stage values (`pipeline.identify.shrinkage`, ``extra``), not pulled toward zero.

Each subset of the offered families (none, each alone, all) is a candidate; a candidate is
*admissible* only when every compliance it estimates is physical, i.e. not negative beyond
`NEGATIVE_SIGMA` of its standard error (a stiffness is positive: a negative compliance absorbs
something else).  Among admissible candidates the one of least model-choice score wins (GCV counting
the physics terms as estimated parameters, or the held-out error of left-out groups — there each fold
re-estimates the compliances from its training groups, anchored at the all-groups registration-stage
values, so the left-out group's rows weigh a little on its own prediction).  A model whose terms were
asked for explicitly (``--physics joint-compliance``: ``forced``) keeps all of them.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

SUFFIXES = {"compliance": "joint-compliance", "lateral1": "lateral-compliance", "lateral2": "lateral-compliance"}
SECOND_ORDER = (".compliance_load",)  # not chosen here (held at 0 unless forced): a load-dependent compliance
# anchored at a registration-stage estimate is the nominal geometry's error again; the group selection offers it
NEGATIVE_SIGMA = 2.0


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
