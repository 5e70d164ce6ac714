"""A soft humanoid's whole physics (`independent_humanoid.write(whole=True)`: every arm joint compliant, lateral
compliance per normal at the torso, shoulders and elbows, stiffness that grows with the load, masses off the
URDF's; no robocal code) fitted with a fixed model structure on one session and applied to another:

* the load-dependent compliance (``J.compliance_load``: δq = c·τ + h·τ|τ|) brings the held-out error to the noise
  floor where the linear compliance alone cannot;
* no compliance is ever estimated negative: a term the data would push below 0 is refused (held at 0, said why);
* the prior the estimates are judged by fits the robot's class (a soft robot is not "implausible" at every joint).
"""

from __future__ import annotations

import numpy as np
import pytest

import independent_humanoid as hu
from humanoid_import import import_humanoid

pytest.importorskip("pinocchio")
NOISE = 2e-4  # m per axis


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    """(model, fit data, other session's data) of the whole humanoid, all gravity families offered."""
    from pipeline.recording.reader import read_recording
    from pipeline.systems.registry import detect, load_with_physics

    tmp = tmp_path_factory.mktemp("whole")
    out = []
    for name, session in (("fit", None), ("test", 2)):
        d = hu.write(tmp / name, seed=3, n=150, noise_m=NOISE, whole=True, session=session)
        rec = read_recording(import_humanoid(d, tmp / f"{name}.mcap"))
        out.append(load_with_physics(detect(rec), rec, "auto", None))
    return out[0][0], out[0][1], out[1][1]


def _held_out(model, data, test, drop=()):
    from pipeline.identify.complexity import fixed_for
    from pipeline.identify.least_squares import FitOptions, fit

    geo = ["registration", "joint offsets", "origin translations", "origin rotations", "joint compliance",
           "lateral compliance", "load-dependent compliance"]
    off = [n for g in drop for n in model.groups()[g]]
    f = fit(model, data, FitOptions(fixed=tuple(set(fixed_for(model, geo)) | set(off)), before=False))
    e = np.asarray(model.residuals(f.x, test), float)
    return f, float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


def test_load_dependent_compliance_reaches_the_noise_floor_and_no_compliance_is_negative(sessions):
    model, data, test = sessions
    floor = np.sqrt(3) * NOISE
    linear_f, linear = _held_out(model, data, test, drop=("load-dependent compliance",))
    f, full = _held_out(model, data, test)
    assert full < 1.15 * floor, (full, floor)  # the stiffening gear modelled: at the floor
    assert full < 0.9 * linear, (full, linear)  # the linear compliance alone is not
    names = model.parameter_names()
    for fit_ in (linear_f, f):
        for i in np.flatnonzero(fit_.free):
            assert not (names[i] in set(model.nonnegative()) and fit_.x[i] < 0), names[i]
    from pipeline.identify.least_squares import NEGATIVE

    refused = [names[i] for i, r in f.identifiability.reasons.items() if r == NEGATIVE]
    assert refused and all(n in set(model.nonnegative()) for n in refused)  # some were, each said why
    load = {n: f.x[i] for i, n in enumerate(names) if n.endswith(".compliance_load") and f.free[i]}
    assert np.median(list(load.values())) < 0  # the gears stiffen under load (h < 0), as the truth's do


def test_the_prior_fits_the_robot_class(sessions):
    from pipeline.accuracy.prior import ROBOT_CLASSES, choose_class, prior_sigma
    from pipeline.identify.plausibility import implausible

    model, data, _ = sessions
    names = model.parameter_names()
    x = np.zeros(len(names))
    free = np.ones(len(names), bool)
    c = [i for i, n in enumerate(names) if n.endswith(".compliance")]
    x[c] = 1 / 2.5e3  # a torque-controlled arm's joints (≈ 2.5·10³ N·m/rad)
    cls = choose_class(model, x, free)
    assert cls["class"] == "torque-controlled" and cls["asked"] == "auto" and "within 3σ" in cls["reason"]
    soft = prior_sigma(model, robot_class=cls["class"])[0]
    assert not [p for p in implausible(model, x, free, soft) if p["name"] in {names[i] for i in c}]
    assert len(implausible(model, x, free, prior_sigma(model)[0])) >= len(c)  # an industrial prior: every joint
    x[c] = 1 / 8e4  # an industrial arm's: the stiffest class
    assert choose_class(model, x, free)["class"] == "industrial"
    assert choose_class(model, x, free, "collaborative")["compliance_sigma"] == ROBOT_CLASSES["collaborative"]["compliance"]
