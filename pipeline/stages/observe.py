"""Stage observe: observability of the campaign at the identified parameters.  Writes observe.json."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.identify.model import take
from pipeline.ingest.tables import model_columns
from pipeline.observe import indices as O
from pipeline.stages.artefacts import read_table, write_json
from pipeline.stages.identify import NAME as IDENTIFY, read_fit
from pipeline.stages.ingest import load_system, read_measurements

NAME = "observe"


def run(run_dir: Path, params: dict) -> dict:
    run_dir = Path(run_dir)
    from pipeline.dynamics.stage import is_dynamics_run, observe as observe_dynamics

    if is_dynamics_run(run_dir):
        return observe_dynamics(run_dir)
    _, model, _ = load_system(run_dir)
    fit = read_fit(run_dir)
    table = read_measurements(run_dir)
    used = read_table(run_dir / IDENTIFY / "residuals.parquet")["used"].astype(bool)
    data = take(model_columns(table), used)
    x = np.asarray(fit["x"], float)
    free = np.asarray(fit["free"], bool)
    names = fit["names"]
    J = model.jacobian(x, data)
    J = J.reshape(-1, J.shape[-1])
    m = J.shape[0]
    s_all = O.singular_values(J)
    s_free = O.singular_values(J[:, free])
    idx = O.indices(s_free, m)
    cov = np.asarray(fit["cov"], float).reshape(int(free.sum()), int(free.sum()))
    C = O.correlation(cov)
    free_names = [n for n, f in zip(names, free) if f]
    pts, Jp = model.points(x, data)
    sig = O.point_sigma(Jp[:, :, free], cov)
    doc = {
        "m_rows": m,
        "singular_values": s_free, "singular_values_all": s_all,
        **idx,
        "index_definitions": {"O1": "(σ1…σL)^(1/L)/√m (Borm & Menq 1991)", "O2": "σmin/σmax (Driels & Pathre 1990)",
                              "O3": "σmin (Nahvi, Hollerbach & Hayward 1994)",
                              "O4": "σmin²/σmax (Nahvi & Hollerbach 1996)",
                              "O5": "1/Σ(1/σi) (Sun & Hollerbach 2008)"},
        "identifiable": free_names,
        "dependencies": {k: v for k, v in fit["reasons"].items()},
        "correlation_names": free_names, "correlation": C,
        "strongest_correlations": O.strongest_correlations(C, free_names),
        "records": np.asarray(data["record"]).astype(int),
        "predicted_points_m": pts,
        "predicted_point_sigma_m": sig,
        "predicted_point_sigma_rms_m": float(np.sqrt(np.mean(sig**2))),
        "predicted_point_sigma_max_m": float(sig.max()),
        "measured_region_m": {"min": pts.min(axis=0), "max": pts.max(axis=0)},
    }
    write_json(run_dir / NAME / "observe.json", doc)
    return {k: doc[k] for k in ("O1", "O2", "O3", "O4", "O5", "predicted_point_sigma_rms_m",
                                "predicted_point_sigma_max_m")} | {
        "n_identifiable": len(free_names), "condition_number": float(s_free[0] / s_free[-1]),
        "singular_values": doc["singular_values"]}
