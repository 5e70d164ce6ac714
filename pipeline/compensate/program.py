"""`robocal compensate` shell: read a run's calibration and a targets CSV, write the program.

Targets CSV (header row; SI units, work frame — the jig frame {W} for the arc welder, the robot
frame {A} for the Delta): ``x,y,z`` (m); optional ``qw,qx,qy,qz`` (tool orientation, unit
quaternion, scalar first); optional ``q_<joint>`` for every joint (the program's nominal joint
angles, rad: the branch to keep); optional ``name``.  Any other column, ``q_`` columns for only some
joints, or a joint angle beyond its limits (degrees given as radians; `importers.bounds`) is a
one-line error naming the file and the column.  Program CSV: per target ``row``, ``name``,
``status``, the calibrated joints ``q_<joint>`` (rad), the corrected target for a nominal
controller ``x_cmd,y_cmd,z_cmd`` (+ ``qw_cmd…`` with orientation), ``predicted_sigma_m`` (1σ
3-D tool-point error of the calibrated model there), ``correction_m``, ``sigma_min_m``,
``model_error_m``.  `RUN_DIR/compensation/compensation.json` keeps the summary for the report.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
from scipy.spatial.transform import Rotation

from pipeline.compensate import serial
from pipeline.errors import RobocalError
from pipeline.importers.bounds import check_bound, check_joints
from pipeline.importers.csv_text import read_columns
from pipeline.importers.csv_text import numbers as parse_numbers

QUAT = ("qw", "qx", "qy", "qz")


def read_targets(path: Path, joint_names: list[str], ranges: tuple | None = None) -> dict:
    """Targets from CSV: p (N,3), R (N,3,3) or None, hint (N,n) or None, names (one-line errors);
    `ranges`: (lower, upper, angular) of the joints (`joint_ranges`), the hints checked against them."""
    hint_cols = [f"q_{j}" for j in joint_names]
    known = ["x", "y", "z", "name", *QUAT, *hint_cols]
    header, t, n_rows = read_columns(path, set(known))
    cols = set(header)
    if unknown := [c for c in header if c not in known]:
        raise RobocalError(f"{path}: column {unknown[0]!r} is not a target column (x,y,z; qw,qx,qy,qz; "
                           f"q_<joint> for {', '.join(joint_names)}; name)")
    if (some := [c for c in hint_cols if c in cols]) and len(some) < len(hint_cols):
        raise RobocalError(f"{path}: nominal joints for some joints only ({', '.join(some)}); give q_<joint> for "
                           f"every joint ({', '.join(hint_cols)}) or none")
    if missing := [c for c in ("x", "y", "z") if c not in cols]:
        raise RobocalError(f"{path}: missing column(s) {', '.join(missing)} (need x,y,z in m)")
    if n_rows == 0:
        raise RobocalError(f"{path}: no targets")

    def numbers(names: list[str]) -> np.ndarray:
        out = np.empty((n_rows, len(names)))
        for k, c in enumerate(names):
            v = parse_numbers(path, c, t[c], first_line=1, where=lambda i, c=c: f"row {i + 1} (line {i + 2}), column {c}")
            bad = np.flatnonzero(~np.isfinite(v))
            if bad.size:
                raise RobocalError(f"{path}: row {bad[0] + 1} (line {bad[0] + 2}), column {c}: missing or not finite")
            check_bound(path, c, v, first_line=1)
            out[:, k] = v
        return out

    p = numbers(["x", "y", "z"])
    R = None
    if cols & set(QUAT):
        if not set(QUAT) <= cols:
            raise RobocalError(f"{path}: orientation needs all of qw,qx,qy,qz (unit quaternion, scalar first)")
        qv = numbers(list(QUAT))
        norm = np.linalg.norm(qv, axis=1)
        if (bad := np.flatnonzero(np.abs(norm - 1) > 1e-6)).size:
            raise RobocalError(f"{path}: row {bad[0] + 1} (line {bad[0] + 2}): quaternion norm {norm[bad[0]]:.6g} is not 1")
        R = Rotation.from_quat(qv[:, [1, 2, 3, 0]]).as_matrix()
    hint = numbers(hint_cols) if set(hint_cols) <= cols else None
    if hint is not None and ranges is not None:
        check_joints(hint, list(joint_names), *ranges,
                     where=lambda i, k: f"{path}: row {i + 1} (line {i + 2}), column {hint_cols[k]}",
                     degrees_hint="compensate reads joints in rad, m for prismatic joints")
    names = list(t["name"]) if "name" in cols else [""] * n_rows
    return {"p": p, "R": R, "hint": hint, "names": names}


def load_run(run_dir: Path) -> dict:
    """The run's system, nominal and calibrated parameters and covariance (identify/fit.json)."""
    from pipeline.stages.ingest import load_system

    fit_path = Path(run_dir) / "identify" / "fit.json"
    if not fit_path.is_file():
        raise RobocalError(f"{run_dir}: no identify/fit.json (calibrate with `robocal run REC --out {run_dir}`)")
    try:
        fit = json.loads(fit_path.read_text())
        if not isinstance(fit, dict) or not isinstance(fit.get("names"), list):
            raise ValueError("not a JSON object with a list of parameter names")
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise RobocalError(f"{fit_path}: not robocal's fit (not valid JSON: {str(e).splitlines()[0][:120]}); "
                           "re-run `robocal run`") from None
    system, model, _ = load_system(Path(run_dir))
    if list(fit["names"]) != list(model.parameter_names()):
        raise RobocalError(f"{fit_path}: parameters do not match the {system.SYSTEM} model of the recording")
    try:
        free = np.asarray(fit["free"], bool)
        cov = np.asarray(fit["cov"], float).reshape(int(free.sum()), int(free.sum()))
        if fit.get("cov_fixture") is not None:  # the fixture's machining tolerance (identify stage)
            cov = cov + np.asarray(fit["cov_fixture"], float).reshape(cov.shape)
        n_used, k = fit.get("n_used"), fit.get("residual_dim")
        dof = int(n_used * k - free.sum()) if n_used is not None and k is not None else None
        out = {"system": system.SYSTEM, "model": model, "x_nominal": np.asarray(fit["nominal"], float),
               "x": np.asarray(fit["x"], float), "free": free, "cov": cov, "dof": dof}
    except (KeyError, TypeError, ValueError, OverflowError) as e:
        raise RobocalError(f"{fit_path}: not robocal's fit ({type(e).__name__}: {str(e)[:120]}); "
                           "re-run `robocal run`") from None
    return out


def point_jacobian(model, x: np.ndarray, free: np.ndarray, q: np.ndarray) -> np.ndarray:
    """d tool point / d free parameters of the calibrated model at joints q, (N, 3, p) m per unit."""
    q = np.nan_to_num(q)
    from pipeline.compensate.tree import TreeKinematics, is_tree_model

    if is_tree_model(model):
        return TreeKinematics.of(model, getattr(model, "payload", ())).point_jacobian(x, q)[:, :, free]
    if _chain_kin(model) is not None:
        J = serial.ChainKinematics.of(model.kin).point_jacobian(x, q)
        Jp = np.zeros((q.shape[0], 3, x.size))
        Jp[:, :, : J.shape[2]] = J
    else:
        _, Jp = model.points(x, {"joint_positions": q})
    return Jp[:, :, free]


def predicted_sigma(model, x: np.ndarray, free: np.ndarray, cov: np.ndarray, q: np.ndarray) -> np.ndarray:
    """1σ 3-D tool-point error of the calibrated model at joints q (N,), m."""
    Jp = point_jacobian(model, x, free, q)
    return np.sqrt(np.einsum("nip,pq,niq->n", Jp, cov, Jp))


def rms_bound95(run: dict, c: serial.Compensated) -> float | None:
    """95 % upper bound on the true RMS 3-D error of the program's ok rows for this one calibration
    (`pipeline.accuracy.propagate.rms_bound`: the predicted RMS is a mean over calibrations; one
    calibration's RMS spreads around it with few effective degrees of freedom), m."""
    from pipeline.accuracy.propagate import rms_bound

    ok = c.status == "ok"
    if not ok.any():
        return None
    return rms_bound(point_jacobian(run["model"], run["x"], run["free"], c.q[ok]), run["cov"], 0.95, run["dof"])


def compensate_run(run: dict, targets: dict, payload: tuple = (), physics: bool = True,
                   tip: str | None = None, approach: int = 0) -> serial.Compensated:
    """Dispatch on the run's model: a URDF tree or a model with physics terms (LM IK of the deflected
    robot under its gravity and `payload`: `pipeline.compensate.tree`), serial arm (LM IK) or Delta
    (closed form; damped Newton for the extended model).  `approach` (−1/0/+1): every joint's direction of
    approach for a calibrated backlash (`TreeKinematics`)."""
    from pipeline.compensate.tree import TreeKinematics, is_tree_model

    model = run["model"]
    if is_tree_model(model):
        kin = TreeKinematics.of(model, payload, tip, physics, approach)
        # the nominal controller: nominal geometry, rigid, placed in the work frame by the calibrated
        # registration (instrument → root, tip → tool point), which no URDF carries
        x_nom = np.asarray(run["x_nominal"], float).copy()
        reg = [i for i, n in enumerate(model.parameter_names()) if n.startswith(("base.", "tool."))]
        x_nom[reg] = np.asarray(run["x"], float)[reg]
        return serial.compensate(kin, x_nom, run["x"], targets["p"], targets["R"],
                                 np.zeros((1, kin.n_joints)), targets["hint"])
    if payload or tip or approach:
        raise RobocalError(f"--payload / --tip / --approach: the {run['system']} model of this run has no physics "
                           "terms or tips")
    if _chain_kin(model) is not None:  # seed 000's arm, a URDF robot: any measurement model over a Chain
        from pipeline.simulate.arc_welder import IK_SEEDS

        kin = serial.ChainKinematics.of(model.kin)
        seeds = IK_SEEDS if kin.n_joints == 6 else np.zeros((1, kin.n_joints))
        return serial.compensate(kin, run["x_nominal"], run["x"], targets["p"], targets["R"], seeds, targets["hint"])
    if hasattr(model, "delta"):
        from pipeline.compensate import delta

        try:
            return delta.compensate(model, run["x_nominal"], run["x"], targets["p"])
        except ValueError as e:
            raise RobocalError(str(e)) from None
    raise RobocalError(f"compensation is not available for system {run['system']} yet")


def check_payload(run: dict, payload: tuple, items=()) -> list[str]:
    """A payload needs a calibrated physics term and a link of the URDF, within the robot's bounds
    (`physics.payload.check_payloads`; `items`: the --payload texts): one-line errors; returns warnings."""
    if not payload:
        return []
    from pipeline.compensate.tree import is_tree_model

    model = run["model"]
    if not is_tree_model(model) or not model.extra_names():
        raise RobocalError(f"--payload: the {run['system']} model of this run has no physics terms (calibrate with "
                           "--physics auto or a list, from a URDF with inertials)")
    import xml.etree.ElementTree as ET

    links = {e.get("name") for e in ET.fromstring(model.kin.urdf).iter("link")}
    for _, link, _ in payload:
        if link not in links:
            raise RobocalError(f"--payload: link {link!r} is not in the run's URDF")
    from pipeline.physics.payload import check_payloads

    kin = model.kin
    return check_payloads(kin.urdf, kin.root, list(kin.tips), list(items) or [f"{m:g}@{ln}" for m, ln, _ in payload],
                          payload, "")


def _chain_kin(model):
    kin = getattr(model, "kin", None)
    return kin if kin is not None and hasattr(kin, "chain") else None


def joint_ranges(model) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(lower, upper, angular) of the calibrated chain's joints in `joint_names` order (None: not a chain)."""
    kin = _chain_kin(model)
    if kin is None or not hasattr(kin, "lower"):
        return None
    joints = getattr(kin, "all_joints", None) or getattr(getattr(kin, "desc", None), "movable", None) or ()
    kind = {j.name: j.type for j in joints if hasattr(j, "type")}
    angular = np.array([kind.get(n, "revolute") != "prismatic" for n in joint_names(model)])
    return np.asarray(kin.lower, float), np.asarray(kin.upper, float), angular


def joint_names(model) -> list[str]:
    kin = _chain_kin(model)
    if kin is not None:
        names = getattr(kin, "joint_names", None)
        return list(names) if names is not None else [j.name for j in kin.joints]
    return ["theta1", "theta2", "theta3"]


def write_program(out: Path, c: serial.Compensated, targets: dict, names: list[str], sigma: np.ndarray) -> None:
    """PROGRAM.csv (see module docstring); doubles written at full precision."""
    cols: dict[str, pa.Array] = {"row": pa.array(np.arange(1, c.q.shape[0] + 1)),
                                 "name": pa.array(targets["names"]), "status": pa.array(c.status.astype(str))}
    for k, j in enumerate(names):
        cols[f"q_{j}"] = pa.array(c.q[:, k])
    for k, a in enumerate("xyz"):
        cols[f"{a}_cmd"] = pa.array(c.p_corrected[:, k])
    if targets["R"] is not None:
        qv = Rotation.from_matrix(c.R_corrected).as_quat()[:, [3, 0, 1, 2]]
        for k, a in enumerate(QUAT):
            cols[f"{a}_cmd"] = pa.array(qv[:, k])
    cols.update({"predicted_sigma_m": pa.array(sigma), "correction_m": pa.array(c.correction_m),
                 "sigma_min_m": pa.array(c.sigma_min_m), "model_error_m": pa.array(c.error_m)})
    out.parent.mkdir(parents=True, exist_ok=True)
    pacsv.write_csv(pa.table(cols), out)


def summary(run: dict, c: serial.Compensated, sigma: np.ndarray, targets_path: Path, out: Path) -> dict:
    """compensation.json: counts per status, per-target σ and correction (for the report)."""
    ok = c.status == "ok"
    return {"system": run["system"], "targets": str(targets_path), "program": str(out), "n_targets": int(c.status.size),
            "status_counts": {s: int((c.status == s).sum()) for s in serial.STATUS if (c.status == s).any()},
            "orientation": bool(np.any(c.R_corrected != np.eye(3))) if run["system"] != "delta-tracker" else False,
            "predicted_sigma_rms_m": float(np.sqrt(np.mean(sigma[ok] ** 2))) if ok.any() else None,
            "predicted_rms_bound95_m": rms_bound95(run, c),
            "correction_median_m": float(np.median(c.correction_m[ok])) if ok.any() else None,
            "max_model_error_m": float(c.error_m[ok].max()) if ok.any() else None,
            "rows": [{"row": i + 1, "status": str(s), "predicted_sigma_m": float(sg), "correction_m": float(cm)}
                     for i, (s, sg, cm) in enumerate(zip(c.status, sigma, c.correction_m))]}
