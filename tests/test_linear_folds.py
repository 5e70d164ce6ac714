"""The model choice's k-fold scores in closed form (`pipeline.identify.linear_folds`, `select(closed_form=True)`).

On a model linear in its parameters the linearisation is exact: every fold's held-out residuals from one basis of
the Jacobian must equal a least-squares fit on the other folds' rows, predicting the fold; and the closed-form
model choice — candidates scored at the solution of the model they extend, only the best solved — must keep the
same groups with the same held-out figures as the choice that refits every candidate on every fold.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from pipeline.identify.complexity import select
from pipeline.identify.least_squares import cross_validate, fit
from pipeline.identify.linear_folds import kfold_at, kfold_linear, scaled_basis

GROUPS = {"registration": ["reg.x", "reg.y", "reg.z"], "upper": ["up.0", "up.1", "up.2"],
          "lower": ["lo.0", "lo.1"], "wrist": ["wr.0", "wr.1", "wr.2"]}


@dataclass(frozen=True)
class Linear:
    """Residuals r = A·x − y per measurement (3 components, m): linear in its parameters, grouped."""

    residual_dim: int = 3

    def parameter_names(self):
        return [n for v in GROUPS.values() for n in v]

    def parameter_units(self):
        return ["m"] * len(self.parameter_names())

    def groups(self):
        return dict(GROUPS)

    def nominal(self):
        return np.zeros(len(self.parameter_names()))

    def residuals(self, x, data):
        return np.einsum("nkp,p->nk", data["A"], np.asarray(x)) - data["y"]

    def jacobian(self, x, data):
        return np.asarray(data["A"], float)


def _campaign(seed: int, n: int = 90):
    """A true error in `upper` (a few mm) and `lower` (tenths of a mm), none in `wrist`; 0.1 mm noise."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, 3, 11))
    A[:, :, :3] = np.eye(3)
    truth = np.r_[rng.normal(0, 0.01, 3), rng.normal(0, 3e-3, 3), rng.normal(0, 3e-4, 2), np.zeros(3)]
    data = {"joint_positions": rng.uniform(-1, 1, (n, 2)), "A": A}
    data["y"] = np.einsum("nkp,p->nk", A, truth) + rng.normal(0, 1e-4, (n, 3))
    return Linear(), data


def test_kfold_linear_equals_a_fit_per_fold():
    rng = np.random.default_rng(1)
    n, kd, p = 40, 3, 5
    J, r = rng.normal(size=(n * kd, p)) * np.r_[1e-3, 1, 10, 1, 0.1], rng.normal(size=n * kd)
    folds = [np.arange(i, n, 4) for i in range(4)]
    got = kfold_linear(J, r, folds, kd)
    for test in folds:
        rows = (test[:, None] * kd + np.arange(kd)).ravel()
        train = np.setdiff1d(np.arange(n * kd), rows)
        d = np.linalg.lstsq(J[train], -r[train], rcond=None)[0]
        np.testing.assert_allclose(got[test].ravel(), r[rows] + J[rows] @ d, rtol=1e-9, atol=1e-12)
    assert scaled_basis(np.c_[J, 2 * J[:, :1]]).shape[1] == p  # a repeated direction is one direction
    U = scaled_basis(np.c_[J[:, 2:], J[:, :1]], base=scaled_basis(J[:, :2]))  # grown from a smaller model's
    assert U.shape[1] == p
    np.testing.assert_allclose(kfold_linear(None, r, folds, kd, U=U), got, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("seed", [0, 3])
def test_closed_form_choice_equals_refitting_every_fold(seed):
    model, data = _campaign(seed)
    ref = select(model, data, k=5, seed=seed)
    got = select(model, data, k=5, seed=seed, closed_form=True)
    assert got.kept == ref.kept and "upper" in got.kept and "wrist" not in got.kept
    assert got.fixed == ref.fixed
    scores = {r["candidate"]: r["holdout_rms_m"] for r in ref.rounds}
    assert len(got.rounds) == len(ref.rounds)
    for a, b in zip(got.rounds, ref.rounds):
        assert a["candidate"] == b["candidate"] and a["kept"] == b["kept"]
        assert a["holdout_rms_m"] == pytest.approx(b["holdout_rms_m"], rel=1e-7), (a, scores)
    assert any(r.get("linearised") for r in got.rounds)  # not every candidate solved
    assert got.holdout_rms_m == pytest.approx(ref.holdout_rms_m, rel=1e-7)


def test_kept_models_kfold_in_closed_form_equals_cross_validation():
    model, data = _campaign(5)
    ref = cross_validate(model, data, k=5, seed=2)
    got = kfold_at(model, data, 5, 2, solution=fit(model, data))
    np.testing.assert_allclose(got, ref, rtol=1e-7, atol=1e-12)
