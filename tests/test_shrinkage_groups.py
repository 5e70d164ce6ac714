"""The left-out-groups model choice scored on the linearised problem (`pipeline.identify.shrinkage_groups`).

On a model linear in its parameters the linearisation is exact, so every candidate's score — linearised at a
different solved candidate — must equal the score of that candidate actually solved and each group actually
refitted without its rows (`group_holdout.held_out`, a real solve per group); the choice must be the eligible
candidate of least held-out RMS, and only registration only, the grid's middle and the winner are solved.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.identify.group_holdout import held_out
from pipeline.identify.shrinkage import _anchor, _penalty, map_solve
from pipeline.identify.shrinkage_groups import shrink_by_groups

REG = ("frame.x", "frame.y", "frame.z")  # an offset shared by every row: the registration group
ROBOT = tuple(f"link.p{i}" for i in range(6))


@dataclass(frozen=True)
class LinearModel:
    """Residuals r = A·x + offset − y per row (3 components, m): a measurement model linear in its parameters."""

    residual_dim: int = 3

    def parameter_names(self):
        return list(REG + ROBOT)

    def groups(self):
        return {"registration": list(REG), "link": list(ROBOT)}

    def nominal(self):
        return np.zeros(len(REG) + len(ROBOT))

    def residuals(self, x, data):
        return np.einsum("nkp,p->nk", data["A"], np.asarray(x)[3:]) + np.asarray(x)[:3] - data["y"]

    def jacobian(self, x, data):
        n = len(data["y"])
        return np.concatenate([np.broadcast_to(np.eye(3), (n, 3, 3)), data["A"]], axis=2)


def _campaign(seed: int, n: int = 60):
    """(model, data, groups, prior σ, registration-only start): rows in 3 groups, each group's A drawn about its
    own mean (what carries over from the others is partial), a true robot error of a few prior σ, 0.1 mm noise."""
    rng = np.random.default_rng(seed)
    g = np.repeat(np.array(["a", "b", "c"]), n // 3)
    A = rng.normal(size=(n, 3, 6)) + rng.normal(size=(3, 3, 6))[np.searchsorted(["a", "b", "c"], g)]
    truth = np.r_[rng.normal(0, 0.01, 3), rng.normal(0, 1e-3, 6)]
    data = {"joint_positions": np.zeros((n, 1)), "A": A, "y": np.zeros((n, 3))}
    model = LinearModel()
    data["y"] = model.residuals(truth, data) + rng.normal(0, 1e-4, (n, 3))
    prior = np.r_[np.ones(3), np.full(6, 5e-4)]
    x0 = model.nominal()
    x0[:3] = np.linalg.lstsq(np.tile(np.eye(3), (n, 1)), -model.residuals(x0, data).ravel(), rcond=None)[0]
    return model, data, g, prior, x0


@settings(max_examples=4, deadline=None)
@given(st.integers(0, 10_000))
def test_linearised_choice_equals_every_candidate_solved_and_refitted(seed):
    model, data, groups, prior, x0 = _campaign(seed)
    s = shrink_by_groups(model, data, prior, x0, groups)
    assert s.fits <= 3  # registration only, the grid's middle, the winner (exact linearisation: no further round)
    free, w = _penalty(model, prior, ())
    weights = {True: w + _anchor(model, prior, ()), False: w}
    centre, idx = np.where(w > 0, model.nominal(), x0), np.flatnonzero(free)
    reg = idx[w[idx] == 0]

    def refitted(anchored, mu):
        """Total held-out RMS (m) of μ with every group really refitted without its rows."""
        if np.isinf(mu):
            def solve(d, xs):
                return map_solve(model, d, xs, reg, np.zeros(reg.size), model.nominal())
        else:
            def solve(d, xs):
                return map_solve(model, d, xs, idx, mu * weights[anchored][idx], centre)
        return held_out(model, data, groups, solve, x0)

    chosen = s.registration == "anchored"
    totals = {}
    for anchored, scores in ((chosen, s.gcv), (not chosen, s.other_registration)):
        for mu, score in scores.items():
            h = refitted(anchored, mu)
            totals[(anchored, mu)] = float(np.sqrt(np.mean(h**2)))
            assert np.isclose(np.sqrt(score), totals[(anchored, mu)], rtol=1e-6), (anchored, mu)
    reference = refitted(True, np.inf)
    per_inf = {g: np.sqrt(np.mean(reference[groups == g] ** 2)) for g in np.unique(groups)}
    ok = [k for k in totals if all(np.sqrt(np.mean(refitted(*k)[groups == g] ** 2)) <= per_inf[g] * (1 + 1e-9)
                                   for g in per_inf)]
    assert (chosen, s.mu_m) == min(ok, key=totals.get)
    assert np.allclose(s.holdout, refitted(chosen, s.mu_m), atol=1e-10)
