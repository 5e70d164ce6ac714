"""Held-out choice of an effect's functional form (a family of forms of one term, chosen by grouped cross-validated RMS, m).

Some library effects come in several forms of the same physics at the same place: a joint
coupling Ji->Jj linear in q_i or quadratic about the campaign's mean angle; the growth of the
links linear in time or a first-order warm-up 1 − e^(−t/τ) with τ on a grid over the
campaign's duration, of every link or of the long links alone.  The forms are candidates like any
other (the selection's grouped F and Holm's correction count them); once the selection has accepted
one, each other form of the same family is tried in its place, and the one with the lowest grouped
cross-validated RMS of the linearised model (geometry + every accepted effect) is kept — unless a simpler form is within one
standard error of it (then the simpler stays): held-out error decides the form, not the in-sample fit.
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.inference import resampling
from pipeline.diagnose.inference.candidate_gram import EXACT_FIT
from pipeline.diagnose.library.term import Effect
from pipeline.identify.linear_folds import scaled_basis


def alternatives(lib: list[Effect], i: int, pool: list[int]) -> list[int]:
    """The other forms of library entry i among the candidate indices `pool`."""
    return [j for j in pool if j != i and lib[j].family == lib[i].family]


def _simpler(a: Effect, b: Effect) -> bool:
    """Is form a simpler than form b: fewer parameters, or as many and a lower `priority`."""
    return (a.k, a.priority) < (b.k, b.priority)


def _within_one_se(e2_a: np.ndarray, e2_b: np.ndarray) -> bool:
    """Does b lower the held-out mean square below a's by at most one standard error of the paired
    difference (per held-out row)?"""
    d = e2_a - e2_b
    return bool(np.mean(d) <= np.std(d, ddof=1) / np.sqrt(d.size))


def _cv(Jf: np.ndarray, S: list[np.ndarray], idx: list[int], r: np.ndarray, folds: list,
        U0: np.ndarray | None = None) -> np.ndarray:
    """Held-out residuals of the geometry Jf and the effects idx; `U0` an orthonormal basis of Jf's columns
    (`linear_folds.scaled_basis`), extended by the effects' columns alone."""
    rows = np.sort(np.concatenate(folds))  # measurements in no fold are not predicted (`resampling.design_folds`)
    U = None if U0 is None else scaled_basis(np.hstack([S[i] for i in idx]), base=U0)
    return resampling.holdout(np.hstack([Jf] + [S[i] for i in idx]), r, folds, U)[rows]


def choose(lib: list[Effect], accepted: list[int], testable: list[int], S: list[np.ndarray], Jf: np.ndarray,
           r: np.ndarray, folds: list) -> tuple[list[int], dict[int, list[dict]]]:
    """(accepted with each finding's form replaced by the held-out best of its family, {kept entry:
    [{form, cv_rms_m}] of every form tried}).  The form with the lowest held-out mean square is kept
    unless a simpler one (fewer parameters, or as many and a lower `priority`: the linear form before a
    warm-up) is within one standard error of the paired difference — then the best of those, and so on
    (the one-standard-error rule): forms that fit equally well out of sample are not told apart by noise.  A form
    that predicts the held-out rows to round-off is not tried (an identity of the model, `candidate_gram.EXACT_FIT`).
    Unchanged when no accepted entry has another form."""
    out = list(accepted)
    tried: dict[int, list[dict]] = {}
    U0 = None
    for pos, i in enumerate(accepted):
        alts = [j for j in alternatives(lib, i, testable) if j not in out]
        if not alts:
            continue
        forms = sorted([i] + alts, key=lambda j: (lib[j].k, lib[j].priority, j))
        U0 = scaled_basis(Jf) if U0 is None else U0  # the geometry's basis, shared by every form
        e2 = {j: _cv(Jf, S, out[:pos] + [j] + out[pos + 1:], r, folds, U0) ** 2 for j in forms}
        # a form with which the model predicts the held-out rows to round-off fits by an identity, not physics
        # (`candidate_gram.EXACT_FIT`): not a form to choose
        floor = EXACT_FIT * float(np.mean(r**2))
        forms = [j for j in forms if j == i or float(np.mean(e2[j])) > floor]
        best = min(forms, key=lambda j: (float(np.mean(e2[j])), lib[j].k, lib[j].priority))
        while True:  # a simpler form within one standard error of the chosen one replaces it
            near = [j for j in forms if _simpler(lib[j], lib[best]) and _within_one_se(e2[j], e2[best])]
            if not near:
                break
            best = min(near, key=lambda j: (float(np.mean(e2[j])), lib[j].k, lib[j].priority))
        out[pos] = best
        tried[best] = [{"form": str(lib[j].location), "cv_rms_m": float(np.sqrt(np.mean(e2[j])))} for j in forms]
    return out, tried
