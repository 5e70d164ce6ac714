"""The touch library's couplings, link growth, face shape and wire terms (`pipeline/diagnose/library/`): signatures against finite
differences of the model, and recovery from the product's simulator."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.diagnose import Settings, diagnose
from pipeline.diagnose.library.term import pick, signature
from pipeline.diagnose.library.touch import touch_library
from pipeline.models import serial_arm
from pipeline.models.jig import stepped_block
from pipeline.simulate import effects as se
from pipeline.simulate.arc_welder import Campaign, Noise
from pipeline.systems import arc_welder as aw

NOM, TRUE, JIG = aw.nominal_arm(), aw.reference_truth(), stepped_block()


def _table(n=60, seed=0):
    rng = np.random.default_rng(seed)
    faces = np.array([f.id for f in JIG.faces])[rng.integers(0, 3, n)]  # the three tops (z)
    return {"joint_positions": rng.uniform(-1, 1, (n, 6)), "axis": np.full(n, 2), "face": faces.astype(object),
            "time_since_start_s": np.linspace(0, 900, n), "normal_sign": np.ones(n)}


def test_thermal_growth_signature_is_the_derivative_of_scaling_every_link_length():
    t, x = _table(), TRUE.vector()
    e = pick(touch_library(TRUE, t), "thermal_growth", "links")
    S = signature(e, TRUE, x, t)[:, 0]
    eps = 1e-7
    names = TRUE.parameter_names()
    lengths = [i for i, nm in enumerate(names) if nm.split(".")[0].startswith("J") and nm.endswith((".d", ".a"))]
    p0 = serial_arm.tip_position(x, t["joint_positions"])[:, 2]
    fd = np.empty(len(p0))
    for r, tau in enumerate(t["time_since_start_s"]):  # each row's lengths grow by eps·τ·L
        xr = x.copy()
        xr[lengths] *= 1 + eps * tau
        fd[r] = (serial_arm.tip_position(xr, t["joint_positions"][r:r + 1])[0, 2] - p0[r]) / eps
    assert np.allclose(S, fd, rtol=1e-5, atol=1e-9)


def test_long_link_warm_up_signature_is_the_derivative_of_scaling_only_the_long_links():
    """`links (warm-up τ = T/4, long links)`: only the links at least ⅓ as long as the longest grow (the
    arc welder's a2 and d4, 0.35 m; not d3, d5 of 0.06–0.08 m), by ε·L·(1 − e^(−t/τ)), τ = T/4."""
    t, x = _table(seed=2), TRUE.vector()
    e = pick(touch_library(TRUE, t), "thermal_growth", "links (warm-up τ = T/4, long links)")
    assert e.data["form"]["links"] == ["J2", "J4"] and e.k == 1
    tau = 0.25 * float(np.max(t["time_since_start_s"]))
    assert e.data["form"]["tau_s"] == pytest.approx(tau)
    S = signature(e, TRUE, x, t)[:, 0]
    names = TRUE.parameter_names()
    grow = [names.index(n) for n in ("J2.a", "J2.d", "J4.a", "J4.d")]
    eps = 1e-7
    p0 = serial_arm.tip_position(x, t["joint_positions"])[:, 2]
    fd = np.empty(len(p0))
    for r, tr in enumerate(t["time_since_start_s"]):
        xr = x.copy()
        xr[grow] *= 1 + eps * (1 - np.exp(-tr / tau))
        fd[r] = (serial_arm.tip_position(xr, t["joint_positions"][r:r + 1])[0, 2] - p0[r]) / eps
    assert np.allclose(S, fd, rtol=1e-5, atol=1e-9)
    assert np.any(np.abs(fd) > 1e-3)  # not a trivially zero signature


def test_joint_coupling_and_wire_signatures_against_finite_differences():
    t, x = _table(seed=1), TRUE.vector()
    q = t["joint_positions"]
    e = pick(touch_library(TRUE, t), "joint_coupling", "J3->J2")
    S = signature(e, TRUE, x, t)[:, 0]
    eps = 1e-7
    dq = np.zeros_like(q)
    dq[:, 1] = eps * q[:, 2]  # δq2 = κ·q3
    fd = (serial_arm.tip_position(x, q + dq)[:, 2] - serial_arm.tip_position(x, q)[:, 2]) / eps
    assert np.allclose(S, fd, rtol=1e-5, atol=1e-9)
    # the wire is the tool frame's z axis (the torch bend is the tool's rotation, ry = −18°), not the flange's
    w = pick(touch_library(TRUE, t), "wire_stickout", "wire")
    Sw = signature(w, TRUE, x, t)[:, 0]
    F = serial_arm.frames(x, q)
    assert np.allclose(F[:, -1, :3, 3], serial_arm.tip_position(x, q), atol=1e-12)  # the last frame is the tool's
    delta = 1e-6  # a wire longer by δ: the tip at T_tool · (0, 0, δ)
    longer = np.einsum("nij,j->ni", F[:, -1], np.array([0.0, 0.0, delta, 1.0]))[:, :3]
    along = (longer[:, 2] - F[:, -1, 2, 3]) / delta
    assert np.allclose(Sw, t["time_since_start_s"] * along, rtol=1e-6, atol=1e-9)
    flange_z = F[:, -2, :3, 2]
    angle = np.degrees(np.arccos(np.clip(np.sum(flange_z * F[:, -1, :3, 2], axis=1), -1, 1)))
    assert np.allclose(angle, 18.0, atol=1e-6)


@pytest.mark.parametrize("spec,name,loc,value", [("thermal_growth=1.5e-6", "thermal_growth", "links", 1.5e-6),
                                                  ("joint_coupling=3e-3@J3->J2", "joint_coupling", "J3->J2", 3e-3)])
def test_recovered_from_the_simulator(spec, name, loc, value):
    c = Campaign(contacts=100, seed=11)
    var = se.Variations(payloads_kg=(0.0, 6.0), search_speeds_m_s=(0.005, 0.01, 0.02))
    targets = se.plan_targets(NOM, JIG, c, truth=TRUE)
    es = se.run(NOM, TRUE, JIG, targets, c, Noise(), [se.parse_effect(spec)], var, seed=5)
    d = diagnose(aw.TouchModel(NOM), se.diagnosis_table(es, JIG), jig_tolerance_m=JIG.tolerance_m,
                 settings=Settings(n_boot=10, repeatability_3sigma_m=1e-4))
    f = [f for f in d["findings"] if (f["effect"], f["location"]) == (name, loc)]
    assert f and abs(f[0]["parameters"][0]["value"] - value) < 0.2 * value
    assert d["status"] == "explained" and not d["noise_floor"]["above_floor"]
