"""Stage accuracy: predicted accuracy over the workspace, the verdict, and the comparison with
a previous calibration.  Writes accuracy/accuracy.json.

Parameters: ``prior`` {name|pattern|kind: σ SI} (command line overrides), ``tolerance_m``,
``targets`` (CSV of x,y,z in m, one target a line, in the model's point frame),
``previous`` (a previous run folder), ``grid`` [nx, ny, nz].
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.accuracy import assess, prior, workspace
from pipeline.accuracy.previous import compare, read_parameters
from pipeline.errors import RobocalError
from pipeline.identify.model import take, uncalibrated
from pipeline.ingest.tables import model_columns
from pipeline.recording.schemas import META_CAMPAIGN, META_FIXTURE, META_ROBOT
from pipeline.stages.artefacts import read_table, write_json
from pipeline.stages.identify import NAME as IDENTIFY, read_fit
from pipeline.stages.ingest import load_system, read_measurements

NAME = "accuracy"


def read_targets(path: str | Path) -> np.ndarray:
    """x,y,z (m) per line; '#' comments and a header line allowed."""
    path = Path(path)
    if not path.is_file():
        raise RobocalError(f"{path}: no such file (--targets)")
    rows = []
    for i, line in enumerate(path.read_text().splitlines(), 1):
        s = line.split("#")[0].strip()
        if not s:
            continue
        parts = [p for p in s.replace(",", " ").split()]
        try:
            v = [float(p) for p in parts]
        except ValueError:
            if not rows and i == 1:
                continue  # header
            raise RobocalError(f"{path}: row {i}: expected x,y,z in m, got {line.strip()!r}") from None
        if len(v) != 3 or not np.all(np.isfinite(v)):
            raise RobocalError(f"{path}: row {i}: expected 3 finite numbers x,y,z in m, got {line.strip()!r}")
        rows.append(v)
    if not rows:
        raise RobocalError(f"{path}: no targets")
    return np.array(rows)


def accuracy_document(model, rec, x, free, cov, data, params: dict, holdout=None, sigma_m=None) -> dict:
    """Everything of the stage but the file writing (also used by `robocal calibrate`).
    `holdout`: (held-out residuals (n, k) over `data`, fold indices) of the run's cross-validation; `sigma_m`:
    a shrinkage fit's σ̂ (`assess.evaluate`)."""
    file_priors = rec.metadata.get(META_ROBOT, {}).get("prior_sigma") or {}
    sigma, kinds, source = prior.prior_sigma(model, file_priors, params.get("prior") or {})
    # a physics term held rigid (the held-out model selection did not keep it) is not part of the stated
    # model: the data showed no sign of it, and the held-out check catches physics the model lacks
    unkept = np.array([k in ("compliance", "load_compliance") for k in kinds]) & ~np.asarray(free, bool)
    sigma = np.where(unkept, 0.0, sigma)
    fixture = rec.metadata.get(META_FIXTURE)
    targets = read_targets(params["targets"]) if params.get("targets") else None
    grid = tuple(int(g) for g in params.get("grid", (6, 5, 3)))
    map_data, what = workspace.map_table(model, x, data, targets, fixture, grid)
    tol = params.get("tolerance_m")
    if tol is None:
        tol = rec.metadata.get(META_CAMPAIGN, {}).get("tolerance_m")
    advise = assess.touch_advice(fixture) if fixture and "faces" in fixture else None
    doc = assess.evaluate(model, x, free, cov, data, sigma, map_data, uncalibrated(model, data),
                          None if tol is None else float(tol), advise, holdout,
                          robot_meta=rec.metadata.get(META_ROBOT, {}), sigma_m=sigma_m)
    doc["map"]["description"] = what
    doc["priors"] = [{"name": n, "kind": k, "sigma": float(s), "source": src, "fixed": not bool(f)}
                     for n, k, s, src, f in zip(model.parameter_names(), kinds, sigma, source, free)]
    doc["note"] = ("Predicted 3-D error (1σ RMS, and the 95 % bound of |error|) of the calibrated point over the map: "
                   "the fitted parameters' covariance plus the prior of every parameter held at nominal, conditioned "
                   "on what this run's data show of it, less what the fit absorbs of it; new_measurement: a new "
                   "session or posture measured as here, the map and one measurement's scatter "
                   "(docs/guide/accuracy.md).")
    return doc


def guarded_document(model, rec, x, free, cov, data, params: dict, holdout=None, sigma_m=None) -> dict:
    """`accuracy_document`, but a model this module cannot map (a new measurement type) gives status
    `not_assessed` with the reason instead of losing the calibration; bad user input still raises."""
    try:
        return accuracy_document(model, rec, x, free, cov, data, params, holdout, sigma_m)
    except RobocalError:
        raise
    except Exception as e:  # noqa: BLE001 — reported in results.json, never silent
        return {"status": "not_assessed", "reason": f"accuracy not assessed: {type(e).__name__}: {e}",
                "advice": "report this model to the robocal maintainers", "map": {}}


def run_holdout(run_dir: Path, res: dict, used: np.ndarray, fit: dict, data: dict | None = None, model=None):
    """(held-out residuals of the used rows, folds) of the identify stage's cross-validation (the
    same seeded split kept representative of the design `data`, `folds.design_folds`, with the rows `model`
    keeps together: a camera's images), or None when it has none."""
    from pipeline.identify.folds import design_folds
    from pipeline.identify.natural_groups import holdout_groups
    from pipeline.stages.artefacts import read_stage

    k = int(fit.get("residual_dim", 1))
    cols = [f"holdout_{j}" for j in range(k)]
    folds = int(fit.get("holdout_folds", 0) or 0)
    if folds < 2 or not all(c in res for c in cols):
        return None
    seed = int(((read_stage(run_dir, IDENTIFY) or {}).get("params") or {}).get("seed", 0))
    h = np.stack([np.asarray(res[c], float) for c in cols], axis=1)[used]
    groups = holdout_groups(model, data) if model is not None and data is not None else None
    return h, design_folds(int(used.sum()), folds, seed, groups, data)


def run(run_dir: Path, params: dict) -> dict:
    run_dir = Path(run_dir)
    from pipeline.dynamics.stage import is_dynamics_run, not_applicable

    if is_dynamics_run(run_dir):
        return not_applicable(NAME)
    _, model, rec = load_system(run_dir)
    fit = read_fit(run_dir)
    table = read_measurements(run_dir)
    res = read_table(run_dir / IDENTIFY / "residuals.parquet")
    used = res["used"].astype(bool)
    data = take(model_columns(table), used)
    x, free = np.asarray(fit["x"], float), np.asarray(fit["free"], bool)
    shrunk = str((fit.get("model_selection") or {}).get("method", "")).startswith("shrinkage")
    doc = guarded_document(model, rec, x, free, fit["cov"], data, params, run_holdout(run_dir, res, used, fit, data, model),
                           fit.get("sigma_m") if shrunk else None)
    if params.get("previous"):
        doc["previous"] = {"run": str(params["previous"]),
                           **compare(fit["parameters"], read_parameters(Path(params["previous"])))}
    write_json(run_dir / NAME / "accuracy.json", doc)
    out = {k: doc[k] for k in ("status", "reason", "advice", "map_rms_1sigma_m", "map_max_1sigma_m",
                               "map_max_bound95_m", "map_uncalibrated_rms_1sigma_m", "tolerance") if k in doc}
    if "new_measurement" in doc:
        out["new_measurement_rms_3d_m"] = doc["new_measurement"]["rms_3d_m"]
    out["status"] = {"pass": "pass", "insufficient": "insufficient", "fail": "tolerance_fail"}.get(doc["status"], "warn")
    if "previous" in doc:
        out["moved_parameters"] = [m["name"] for m in doc["previous"]["moved"]]
    return out


def read_accuracy(run_dir: Path) -> dict | None:
    from pipeline.stages.artefacts import read_json

    p = Path(run_dir) / NAME / "accuracy.json"
    return read_json(p) if p.is_file() else None
