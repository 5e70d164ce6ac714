"""The dynamics diagnosis against an independent generator (tests/independent_dynamics.py: Pinocchio's RNEA of
a perturbed URDF, friction and drive physics and a trajectory written there, no robocal code), through the
user's path: the generator's CSV tables → `robocal import csv --measure effort` → `robocal run` → diagnosis.json.

A clean campaign: nothing found, the base parameters within their stated σ of the truth.  The same design with
three forms injected at 4× the minimum detectable size the clean campaign's gate states: each named at its
joint, and the held-out torque error falls; beside them friction falling with load (a sign no drive's friction
has): selected, but not named.  The library's elastic-lag forms against the generator's elastic joint, in the
part of the torque the base parameters leave.  (Every form over 20 seeds: benchmarks/bench_dynamics_diagnosis.py.)
"""

from __future__ import annotations

import json
from pathlib import Path

import independent_dynamics as G
import numpy as np
import pytest

from conftest import run_cli

SEED, DURATION_S = 4, 30.0


def _campaign(d: Path, name: str, effects: dict | None = None):
    t, q, v, a = G.trajectory(SEED, DURATION_S)
    e, truth = G.efforts(SEED, t, q, v, a, effects=effects)
    pos, vel, eff = G.write_tables(d / name, t, q, v, e)
    rec = d / f"{name}.mcap"
    run_cli("import", "csv", str(pos), "--velocity-csv", str(vel), "--effort-csv", str(eff), "--urdf",
            str(d / "gen.urdf"), "--root", "base", "--tip", "s4", "--measure", "effort", "--effort-units", "Nm",
            "--out", str(rec), check=True)
    run_cli("run", str(rec), "--out", str(d / f"run_{name}"), "--stages", "ingest,validate,identify,observe,diagnose",
            check=True)
    fit = json.loads((d / f"run_{name}" / "identify" / "fit.json").read_text())
    diag = json.loads((d / f"run_{name}" / "diagnose" / "diagnosis.json").read_text())
    return fit, diag, truth


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    d = tmp_path_factory.mktemp("dyn_diag")
    (d / "gen.urdf").write_text(G.ARM)
    return (d, *_campaign(d, "clean"))


def test_clean_campaign_finds_nothing_and_the_base_parameters_are_within_their_sigma(clean):
    from pipeline.dynamics import design
    from pipeline.dynamics import identify as I
    from pipeline.dynamics import rigid_body as RB

    _, fit, diag, truth = clean
    assert diag["family"] == "dynamics" and diag["findings"] == [], diag["findings"]
    assert diag["status"] == "clean", diag["status_reason"]
    assert diag["holdout_rms_before_m"] < 1.2 * 0.05  # the model fits the generator's data to its noise
    # the truth's base parameters (robocal's base set of the chosen model, applied to the generator's θ)
    c = fit["model_choice"]
    terms = design.Terms(friction=tuple(c["friction"]), armature=c["armature"], coulomb_width=c["coulomb_width"])
    rb = RB.build(G.ARM, G.JOINTS)
    base = I.structural_base(rb, np.ones(4, bool), terms)
    assert fit["names"][40:44] == ["a1.fv", "a1.fc", "a1.f0", "a1.Ia"]
    beta_true = base.beta(G.true_parameters(truth))
    z = (np.asarray(fit["beta"]) - beta_true) / np.asarray(fit["beta_std"])
    assert len(z) == base.rank and np.sqrt(np.mean(z**2)) < 1.5 and np.abs(z).max() < 4.0, np.round(z, 2)


def _mds(diag: dict, effect: str, joint: str | None, pick=None) -> float:
    rows = [c for c in diag["candidates"] if c["effect"] == effect and c["min_detectable"] is not None
            and (joint is None or c["location"].split(" (")[0] == joint)]
    return (pick(rows) if pick else rows[0])["min_detectable"]


def test_forms_injected_at_four_times_their_detectable_size_are_named_and_the_held_out_error_falls(clean):
    d, _, diag, _ = clean
    stribeck = _mds(diag, "stribeck", "a2", lambda rows: min(rows, key=lambda c: abs(np.log(
        float(c["location"].split("v_s ")[1].split()[0]) / 0.05))))
    spring = _mds(diag, "cable_spring", "a3")
    offset = min(c["min_detectable"] for c in diag["candidates"] if c["effect"] == "time_offset")
    load = _mds(diag, "load_friction", "a4")
    # and friction *falling* with load on a4: a physics no drive has, which the selection sees and the
    # diagnosis must not name as load-dependent friction (its sign is not that physics)
    effects = {"stribeck": (1, 4 * stribeck, 0.05), "cable_spring": (2, 4 * spring, 0.0),
               "time_offset": (None, 4 * offset, None), "load_friction": (3, -6 * load, None)}
    _, found, _ = _campaign(d, "injected", effects)
    names = {(f["effect"], f["location"].split(" (")[0]) for f in found["findings"]}
    for want in (("stribeck", "a2"), ("cable_spring", "a3"), ("time_offset", "effort stream")):
        assert want in names, (want, names)
    assert ("load_friction", "a4") not in names
    assert any(f["effect"] == "load_friction" and f["location"] == "a4" and "sign" in f["note"]
               for f in found["rejected_findings"]), [(f["effect"], f["location"]) for f in found["rejected_findings"]]
    assert found["holdout_rms_after_m"] < found["holdout_rms_before_m"]
    spring_fd = next(f for f in found["findings"] if f["effect"] == "cable_spring")
    k = spring_fd["parameters"][0]
    assert abs(k["value"] - 4 * spring) < 4 * k["std"] + 0.25 * 4 * spring  # its size, as injected


def test_the_elastic_lag_form_matches_the_generators_elastic_joint_beyond_what_the_base_parameters_take():
    """The generator's elastic joint (the link lagging the motor-side reading by c·τ, its own fixed point on RNEA)
    against the library's first-order forms, in the part of the torque the base parameters cannot take (what the
    diagnosis sees): a resonance form leaves far less of it than the rates of the identification's whole band
    (whose τ̈ holds content above the link's motion), and recovers c."""
    from pipeline.diagnose.adapters import dynamics as AD
    from pipeline.diagnose.library import drive
    from pipeline.dynamics import identify as I
    from pipeline.dynamics import rigid_body as RB

    c = 3e-4  # rad/(N·m): a 3300 N·m/rad joint
    t, q, v, a = G.trajectory(SEED, DURATION_S)
    e, _ = G.efforts(SEED, t, q, v, a)
    ei, _ = G.efforts(SEED, t, q, v, a, effects={"joint_elasticity": (1, c, None)})  # the same noise draw
    rb = RB.build(G.ARM, G.JOINTS)
    data = I.Data(t, q, ei, np.ones(4, bool))
    tab = AD.table(rb, data, I.identify(rb, data))
    T, F, P = tab["X"].shape
    Q, _ = np.linalg.qr(tab["X"].reshape(T * F, P))
    d = (ei - e).ravel()
    d -= Q @ (Q.T @ d)
    left, c_hat = {}, {}
    for fr in drive.RESONANCE_FORMS_HZ + (50.0,):  # 50 Hz: Nyquist, the identification's own band
        b = drive.joint_elasticity(tab, 1, fr).basis(None, None, tab)[:, :, 0].ravel()
        b -= Q @ (Q.T @ b)
        c_hat[fr] = float(b @ d / (b @ b))
        left[fr] = float(np.linalg.norm(d - c_hat[fr] * b) / np.linalg.norm(d))
    best = min(drive.RESONANCE_FORMS_HZ, key=left.get)
    assert left[best] < 0.6 * left[50.0] and abs(c_hat[best] / c - 1) < 0.1, (left, c_hat)


def test_the_held_out_gain_is_judged_against_the_noise_not_against_where_the_effect_is_largest():
    """An effect larger in one 2 s block than elsewhere is no less sure a gain; a term fitted to noise is a loss."""
    from pipeline.diagnose.adapters.dynamics_diagnosis import gain_z

    rng = np.random.default_rng(2)
    fs, T, F = 100.0, 4000, 2
    e = rng.normal(0, 0.05, (T, F))
    s = np.full((T, F), 0.01)
    s[800:1000] = 0.15  # the effect under the largest accelerations: one block of twenty
    assert gain_z(e + s, e, fs) > 5  # the scatter of the blocks' gains alone put it at 1.3
    overfit = rng.normal(0, 0.01, (T, F))  # a term's held-out prediction where it is only noise
    assert gain_z(e, e - overfit, fs) < 0


def test_an_asymmetric_coulomb_level_is_named_from_the_rests_and_does_not_pull_the_model_choice(clean):
    """A Coulomb level higher one way (+f_a while the joint moves, the generator's rests without it) is, on the
    moving rows, the joint's offset; only the rests — where a held joint's friction lies within ± its Coulomb
    level — separate them.  Injected at 4× the size the clean gate states for it (beyond that band): named at its
    joint with its size, nothing else beside it, and the model chosen as on the clean campaign (the rests' misfit
    no longer pulls the choice to a low cut-off or to no Coulomb term, and the Stribeck terms that model's misfit
    drew are gone)."""
    from pipeline.diagnose.adapters.dynamics_diagnosis import diagnose
    from pipeline.diagnose.method import Settings
    from pipeline.dynamics import identify as I
    from pipeline.dynamics import rigid_body as RB

    _, fit, diag, _ = clean
    gate = next(c for c in diag["candidates"] if c["effect"] == "asymmetric_coulomb" and c["location"] == "a3")
    assert gate["identifiable"], gate  # the rests show it: its band (a3's Coulomb level, 0.7 N·m) and a little more
    size = 4 * gate["min_detectable"]
    t, q, v, a = G.trajectory(SEED, DURATION_S)
    e, _ = G.efforts(SEED, t, q, v, a, effects={"asymmetric_coulomb": (2, size, None)})
    rb = RB.build(G.ARM, G.JOINTS)
    data = I.Data(t, q, e, np.ones(4, bool))
    f = I.identify(rb, data)
    structure = f.choice.label().rsplit(", ", 1)[0]  # cut-off, terms, Coulomb width (the solvers tie here)
    assert structure == fit["model_choice"]["label"].rsplit(", ", 1)[0], (f.choice.label(), fit["model_choice"])
    doc = diagnose(rb, data, f, Settings(n_boot=0))
    assert [(x["effect"], x["location"]) for x in doc["findings"]] == [("asymmetric_coulomb", "a3")], doc["findings"]
    p = doc["findings"][0]["parameters"][0]
    assert abs(p["value"] - size) < 0.05 * size, (p, size)
    assert doc["holdout_rms_after_m"] < 0.5 * doc["holdout_rms_before_m"]
