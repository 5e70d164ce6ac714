"""What makes a fit with physics terms cheap must not change what it finds: the independent humanoid
(no robocal code: dual arm, coupled torso, whole-tree gravity, joint and lateral compliance) with every
physics family offered.

* `TreePointModel.jacobian_columns` (only the free columns) against finite differences of the
  residuals, and bit for bit against the full Jacobian's columns;
* `TreePointModel.without` (terms held at 0 dropped: shorter chains) has the same residuals and the
  same Jacobian columns, bit for bit, and `held_columns` gives the dropped terms' columns bit for bit;
* `fit` with terms held at 0 (fitted through `without`) against the fit on the whole model, bit for
  bit (both under one BLAS thread, as `fit` runs): parameters, free set, every reason, σ — for the rigid round of a model choice and for one
  that keeps the joint compliance and drops the rest; the same through `SessionFrames`.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import run_cli

import independent_humanoid as hu

pytest.importorskip("pinocchio")


@pytest.fixture(scope="module")
def auto(tmp_path_factory):
    """The humanoid's model with every physics family (`--physics auto`) and its table."""
    from pipeline.recording.reader import read_recording
    from pipeline.systems.registry import detect, load_with_physics

    d = hu.write(tmp_path_factory.mktemp("humanoid") / "data", seed=5, n=60, noise_m=2e-4,
                 scale={"left_j4": 4e-3})
    rec = d.parent / "humanoid.mcap"
    r = run_cli("import", "csv", d / "postures.csv", "--urdf", d / "humanoid.urdf", "--root", "base",
                "--tip", "left_hand=lx,ly,lz", "--tip", "right_hand=rx,ry,rz", "--coupled",
                "torso_j3=-torso_j1-torso_j2", "--measure", "point", "--out", rec)
    assert r.returncode == 0, r.stderr
    rd = read_recording(rec)
    model, table = load_with_physics(detect(rd), rd, "auto", None)
    assert model.compliant and model.kin.lateral and model.encoder  # every family offered
    return model, table


def _physics(model) -> list[str]:
    from pipeline.physics.summary import physics_names

    return physics_names(model)


def test_free_columns_match_finite_differences_and_the_full_jacobian(auto):
    model, table = auto
    names = model.parameter_names()
    rng = np.random.default_rng(3)
    x = model.initial_guess(table)
    phys = [names.index(n) for n in _physics(model)]
    x[phys] = rng.uniform(-3e-5, 3e-5, len(phys))  # every term away from 0: its columns are not trivial
    load = {i for i in phys if names[i].endswith(".compliance_load")}  # rad/(N·m)²: times τ² (10⁴ N²·m² at the torso)
    x[list(load)] *= 1e-3
    free = rng.random(len(names)) < 0.3
    free[phys[::4]] = True
    free[names.index("torso_j1.offset")] = True
    Jc = model.jacobian_columns(x, table, free)
    assert Jc.shape == (len(table["position"]), 3, int(free.sum()))
    assert np.array_equal(Jc, model.jacobian(x, table)[:, :, free])
    for c, i in enumerate(np.flatnonzero(free)[::3]):
        h = 1e-10 if i in load else 1e-7
        e = np.zeros_like(x)
        e[i] = h
        fd = (model.residuals(x + e, table) - model.residuals(x - e, table)) / (2 * h)
        col = Jc[:, :, 3 * c]
        assert np.abs(fd - col).max() <= 1e-6 * max(1.0, np.abs(col).max()), names[i]


def test_without_the_terms_held_at_zero_nothing_else_changes(auto):
    model, table = auto
    names = model.parameter_names()
    lateral = [n for n in _physics(model) if n.endswith((".lateral1", ".lateral2"))]
    small = model.without(lateral + [n for n in _physics(model) if ".ecc_" in n] + [lateral[0].rsplit(".", 1)[0]])
    assert small.kin.lateral == () and small.compliant == model.compliant
    assert all(".ecc_" not in n for n in small.encoder) and any(".scale" in n for n in small.encoder)
    keep = [names.index(n) for n in small.parameter_names()]
    assert keep == sorted(keep)  # the same order: a subsequence of the whole model's parameters
    rng = np.random.default_rng(4)
    x = model.initial_guess(table)
    x[keep] += rng.normal(0, 1e-4, len(keep))  # kept terms away from 0, the dropped ones at 0
    assert np.array_equal(model.residuals(x, table), small.residuals(x[keep], table))
    assert np.array_equal(model.jacobian(x, table)[:, :, keep], small.jacobian(x[keep], table))
    from pipeline.identify.least_squares import _flat_jac, _whole_jacobian

    x[[i for i in range(len(names)) if i not in keep]] = 0.0
    gone = np.setdiff1d(np.arange(len(names)), keep)  # the dropped terms' columns from the smaller chains
    assert np.array_equal(small.held_columns(x[keep], table, [names[i] for i in gone]),
                          model.jacobian(x, table)[:, :, gone])
    assert np.array_equal(_whole_jacobian(small, model, np.array(keep), x[keep], x, table, None),
                          _flat_jac(model, x, table))
    assert model.without(["base.x", "torso_j1.offset"]) is model  # geometry is never dropped
    one = model.without([lateral[0]])  # half a lateral pair: its virtual joints stay
    assert one.kin.lateral == model.kin.lateral


@pytest.mark.parametrize("kept", [(), ("joint compliance", "origin translations")])
def test_a_fit_with_terms_held_at_zero_is_the_whole_models_bit_for_bit(auto, kept):
    from pipeline.identify.complexity import fixed_for
    from pipeline.blas import single_threaded  # as `fit` runs: one BLAS thread, the same rounding
    from pipeline.identify.least_squares import FitOptions, _fit, _fit_once

    model, table = auto
    opts = FitOptions(fixed=fixed_for(model, ["registration", *kept]))
    assert set(_physics(model)) - set(model.groups()["joint compliance"]) <= set(opts.fixed)
    # `fit`'s one solve (before it refuses negative compliances, `fit` itself): through the smaller model
    reduced, whole = single_threaded(_fit_once)(model, table, opts), single_threaded(_fit)(model, table, opts)[0]
    _same(reduced, whole)


def test_sessions_keep_their_frames_when_terms_are_dropped(auto):
    from pipeline.identify.complexity import fixed_for
    from pipeline.blas import single_threaded  # as `fit` runs: one BLAS thread, the same rounding
    from pipeline.identify.least_squares import FitOptions, _fit, fit
    from pipeline.measurements.sessions import SessionFrames

    model, table = auto
    two = SessionFrames(model, 2)
    data = dict(table, session=(np.arange(len(table["position"])) % 2).astype(int))
    small = two.without(_physics(model))
    assert isinstance(small, SessionFrames) and small.inner.kin.lateral == () and small.n_sessions == 2
    opts = FitOptions(fixed=fixed_for(two, ["registration", "joint offsets"]))
    _same(fit(two, data, opts), single_threaded(_fit)(two, data, opts)[0])


def _same(a, b) -> None:
    assert a.names == b.names
    assert np.array_equal(a.x, b.x) and np.array_equal(a.nominal, b.nominal)
    assert np.array_equal(a.free, b.free) and a.identifiability.reasons == b.identifiability.reasons
    assert list(a.identifiability.reasons) == list(b.identifiability.reasons)  # the same order too
    assert np.array_equal(a.std, b.std) and np.array_equal(a.cov, b.cov)
    assert np.array_equal(a.residuals_before, b.residuals_before) and np.array_equal(a.residuals_after,
                                                                                     b.residuals_after)
    assert np.array_equal(a.identifiability.order, b.identifiability.order)
    assert a.sigma == b.sigma and a.nfev == b.nfev


def test_an_unknown_fixed_name_is_still_refused(auto):
    from pipeline.identify.least_squares import FitOptions, fit

    model, table = auto
    with pytest.raises(ValueError, match="cannot fix unknown parameters: \\['nope.x'\\]"):
        fit(model, table, FitOptions(fixed=(*_physics(model), "nope.x")))
