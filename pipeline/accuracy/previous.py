"""Compare a calibration with the robot's previous one: which parameters moved by more than 3σ."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError

MOVED_SIGMAS = 3.0


def read_parameters(run_dir: Path) -> dict[str, dict]:
    """{name: {estimate, std, identifiable}} of a previous run (`robocal run` or `robocal calibrate` folder)."""
    run_dir = Path(run_dir)
    for p in (run_dir / "identify" / "fit.json", run_dir / "results.json"):
        if not p.is_file():
            continue
        try:
            doc = json.loads(p.read_text())
        except ValueError as e:
            raise RobocalError(f"{p}: not JSON ({e})") from None
        rows = doc.get("parameters")
        if rows:
            return {r["name"]: {"estimate": float(r["estimate"]), "std": float(r.get("std") or 0.0),
                                "identifiable": bool(r.get("identifiable", True)), "unit": r.get("unit", "")}
                    for r in rows}
    raise RobocalError(f"{run_dir}: no previous calibration found (looked for identify/fit.json and results.json "
                       f"with parameters)")


def compare(current: list[dict], previous: dict[str, dict], k: float = MOVED_SIGMAS) -> dict:
    """Parameters identified in both runs whose change exceeds k·sqrt(σ_now² + σ_before²)."""
    moved, compared = [], 0
    for r in current:
        p = previous.get(r["name"])
        if p is None or not (r["identifiable"] and p["identifiable"]):
            continue
        compared += 1
        s = float(np.hypot(r["std"], p["std"]))
        d = r["estimate"] - p["estimate"]
        if s > 0 and abs(d) > k * s:
            moved.append({"name": r["name"], "unit": r["unit"], "previous": p["estimate"], "now": r["estimate"],
                          "change": d, "sigma": s, "z": d / s})
    moved.sort(key=lambda m: -abs(m["z"]))
    return {"compared": compared, "threshold_sigma": k, "moved": moved}
