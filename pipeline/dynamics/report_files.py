"""The files a dynamics identification writes: fit.json's document, the predictor, the per-sample torque
table, model.urdf with the identified inertials, and the friction / drive sidecar (YAML).  Pure: each
function returns a document or text; `pipeline.dynamics.stage` writes them."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from pipeline.dynamics import signals
from pipeline.dynamics.crossval import rms
from pipeline.dynamics.identify import Data, Fit, fitted_rows, nominal_torques
from pipeline.dynamics.rigid_body import RigidBody, link_parameters, regressor
from pipeline.dynamics.solve import is_consistent


def _terms(fit: Fit) -> dict:
    t = fit.choice.terms
    return {"friction": list(t.friction), "armature": t.armature, "coulomb_width": t.coulomb_width,
            **({"motors": [[n, list(g)] for n, g in t.motors]} if t.motors else {})}


def _scored(data) -> str:
    """What the held-out figures are scored on: the raw torques, or those of a fast log decimated
    (`signals.decimate`) to the rate the model works at."""
    from pipeline.dynamics.signals import sample_rate

    if getattr(data, "decimation", 1) <= 1:
        return "raw torques at the recorded rate"
    fs = sample_rate(data.t)
    return (f"torques decimated ×{data.decimation} to {fs:.0f} Hz (positions and torques through the same "
            f"anti-alias low-pass at {0.4 * fs:.0f} Hz; robocal evaluate scores every recorded sample)")


def fit_document(rb: RigidBody, model, fit: Fit, data: Data) -> dict:
    """fit.json: the identified dynamics model (N·m; N for a prismatic joint)."""
    joints = [j for j, f in zip(model.joints, model.fit_mask) if f]
    base = fit.base
    bnames = [base.combination(fit.names, k) for k in range(base.rank)]
    sol = fit.solution
    # covariance of the base parameters (the chosen solver's rows; OLS scale) for observe's correlations
    qf, v, a = signals.derivatives(data.t, data.q, fit.choice.cutoff_hz)
    from pipeline.dynamics import design

    X = design.matrix(regressor(rb, qf, v, a), v, a, model.fit_mask, fit.choice.terms)[:, :, base.independent]
    use = fitted_rows(v[:, model.fit_mask], fit.choice.terms).reshape(-1)  # the rows the fit used (not a crawl's)
    A = X.reshape(-1, base.rank)
    s = np.sqrt(np.einsum("ij,ij->j", A, A))
    s = np.where(s > 0, s, 1.0)
    sv = np.linalg.svd(A / s, compute_uv=False)
    r = (A @ sol.beta if sol.beta.size == base.rank else A @ base.beta(sol.theta)) - \
        np.asarray(data.tau, float)[:, model.fit_mask].reshape(-1)
    Au, ru = A[use] / s, r[use]
    s2 = float(ru @ ru) / max(int(use.sum()) - base.rank, 1)
    cov = np.linalg.pinv(Au.T @ Au) / np.outer(s, s) * s2
    nominal = nominal_torques(rb, data, model.fit_mask, fit.choice.cutoff_hz)
    rn = nominal - data.tau[:, model.fit_mask]
    cons = fit.consistent
    n = 10 * rb.n_joints
    doc = {
        "system": "urdf", "family": "dynamics", "n_measurements": int(data.t.size), "fit_joints": joints,
        "decimation": int(getattr(data, "decimation", 1)),
        "n_parameters": len(fit.names), "n_identifiable": base.rank,
        "condition_number": float(sv[0] / sv[-1]), "condition_number_unscaled": fit.condition,
        "singular_values": sv.tolist(),
        "model_choice": {"cutoff_hz": fit.choice.cutoff_hz, "solver": fit.choice.solver, **_terms(fit),
                         "label": fit.choice.label(), "candidates": fit.candidates,
                         "arbiter": "contiguous-block cross-validation (5 blocks, 0.5 s guard), held-out torque RMS "
                                    "pooled over the fitted joints, " + _scored(data)},
        "model_choice_label": fit.choice.label(),
        "rms_after_Nm": float(rms(fit.rms_train)), "holdout_rms_Nm": float(rms(fit.rms_cv)),
        "rms_after_joint_Nm": dict(zip(joints, fit.rms_train.tolist())),
        "holdout_rms_joint_Nm": dict(zip(joints, fit.rms_cv.tolist())),
        "nominal_rms_joint_Nm": dict(zip(joints, rms(rn, axis=0).tolist())),
        "nominal_rms_Nm": float(rms(rn)),
        "holdout_kind": "contiguous blocks of the recording, each predicted by a model fitted on the others",
        "units": "N·m (N for a prismatic joint)",
        "names": fit.names, "parameter_units": fit.units, "theta": fit.theta.tolist(),
        "base_names": bnames, "beta": base.beta(fit.theta).tolist(), "beta_std": np.sqrt(np.diag(cov)).tolist(),
        "base_cov": cov.tolist(),
        "effort": model.effort, "timings_s": fit.timings, "warnings": [], "status": "pass",
    }
    if cons is not None:
        doc["consistent"] = {"theta": cons.theta.tolist(), "bodies_consistent": is_consistent(
            cons.theta[:n] - rb.carried).tolist(), "holdout_rms_joint_Nm": None if fit.rms_cv_consistent is None
            else dict(zip(joints, np.asarray(fit.rms_cv_consistent).tolist())),
            "rms_after_Nm": _rms_of(rb, fit, data, cons.theta)}
    return doc


def _rms_of(rb: RigidBody, fit: Fit, data: Data, theta: np.ndarray) -> float:
    from pipeline.dynamics import design

    qf, v, a = signals.derivatives(data.t, data.q, fit.choice.cutoff_hz)
    X = design.matrix(regressor(rb, qf, v, a), v, a, data.fit, fit.choice.terms)
    return float(rms(X @ theta - data.tau[:, data.fit]))


def predictor_document(model, fit: Fit) -> dict:
    """dynamics.json: what `identify.predict` needs to predict another recording without refitting."""
    return {"joints": list(model.joints), "fit_joints": [j for j, f in zip(model.joints, model.fit_mask) if f],
            "cutoff_hz": fit.choice.cutoff_hz, "solver": fit.choice.solver, "terms": _terms(fit),
            "names": fit.names, "units": fit.units, "theta": fit.theta.tolist()}


def torque_table(rb: RigidBody, fit: Fit, data: Data, model) -> dict[str, np.ndarray]:
    """Per sample: time (s), and per fitted joint the measured, fitted and held-out predicted torque."""
    from pipeline.dynamics import design

    qf, v, a = signals.derivatives(data.t, data.q, fit.choice.cutoff_hz)
    X = design.matrix(regressor(rb, qf, v, a), v, a, model.fit_mask, fit.choice.terms)
    fitted = X @ fit.theta
    meas = data.tau[:, model.fit_mask]
    out = {"t_s": data.t}
    for k, j in enumerate(j for j, f in zip(model.joints, model.fit_mask) if f):
        col = list(model.joints).index(j)
        out[f"measured_{j}"] = meas[:, k]
        out[f"fitted_{j}"] = fitted[:, k]
        if fit.cv_residuals is not None:
            out[f"holdout_{j}"] = meas[:, k] + fit.cv_residuals[:, k]
        out[f"q_{j}"] = data.q[:, col]
        out[f"v_{j}"] = v[:, col]
    return out


def _fixed_children(root: ET.Element, link: str) -> list[str]:
    """Links attached to `link` through fixed joints, recursively (Pinocchio merges them into its body)."""
    out, todo = [], [link]
    while todo:
        cur = todo.pop()
        for j in root.iter("joint"):
            if j.get("type") == "fixed" and j.find("parent").get("link") == cur:
                child = j.find("child").get("link")
                out.append(child)
                todo.append(child)
    return out


def identified_urdf(model, rb: RigidBody, fit: Fit) -> str:
    """The URDF with each recorded joint's child link carrying its identified, physically consistent inertia
    (`fit.consistent`; the URDF's own where there is none).  Links fixed to it are merged into it (their
    <inertial> removed: the rigid body is the same); links behind joints that were not recorded keep theirs."""
    import pinocchio as pin

    root = ET.fromstring(model.urdf)
    theta = fit.consistent.theta if fit.consistent is not None else None
    links = {lk.get("name"): lk for lk in root.iter("link")}
    own = link_parameters(rb) if theta is None else theta[:10 * rb.n_joints] - rb.carried
    for k, name in enumerate(rb.links):
        if name not in links:
            continue
        for child in _fixed_children(root, name):
            el = links.get(child)
            if el is not None and el.find("inertial") is not None:
                el.remove(el.find("inertial"))
        el = links[name]
        if el.find("inertial") is not None:
            el.remove(el.find("inertial"))
        inertia = pin.Inertia.FromDynamicParameters(np.asarray(own[10 * k:10 * k + 10], float))
        c, I = inertia.lever, inertia.inertia
        ine = ET.SubElement(el, "inertial")
        ET.SubElement(ine, "origin", xyz=" ".join(f"{x:.9g}" for x in c), rpy="0 0 0")
        ET.SubElement(ine, "mass", value=f"{inertia.mass:.9g}")
        ET.SubElement(ine, "inertia", ixx=f"{I[0, 0]:.9g}", ixy=f"{I[0, 1]:.9g}", ixz=f"{I[0, 2]:.9g}",
                      iyy=f"{I[1, 1]:.9g}", iyz=f"{I[1, 2]:.9g}", izz=f"{I[2, 2]:.9g}")
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n"


def sidecar_yaml(model, fit: Fit) -> str:
    """dynamics.yaml: per fitted joint its friction and armature (SI) and the drive's effort declaration."""
    import yaml

    theta = fit.consistent.theta if fit.consistent is not None else fit.theta
    joints = {}
    for name, unit, v in zip(fit.names, fit.units, theta):
        j, _, key = name.rpartition(".")
        if key in ("fv", "fc", "f0", "Ia"):
            joints.setdefault(j, {})[key] = {"value": float(v), "unit": unit}
    doc = {"model": "τ = Y(q, q̇, q̈)·π + fv·q̇ + fc·tanh(q̇/w) + f0 + Ia·q̈"
                    + (" + Σ_motors G·(fv·u + fc·tanh(u/w) + Ia·u̇), u = G·q̇" if fit.choice.terms.motors else ""),
           **({"motors": {n: list(g) for n, g in fit.choice.terms.motors}} if fit.choice.terms.motors else {}),
           "coulomb_width": fit.choice.terms.coulomb_width, "joints": joints, "effort": model.effort}
    return yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)
