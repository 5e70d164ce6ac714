"""DIR/results.json: the machine-readable figures of every stage of a run (SI units)."""

from __future__ import annotations

from pathlib import Path

from pipeline import __version__
from pipeline.stages.artefacts import read_stage
from pipeline.stages.registry import STAGES

HEADLINE = ("system", "n_measurements", "n_used", "rms_before_m", "rms_after_m", "holdout_rms_m",
            "n_identifiable", "n_parameters", "predicted_point_sigma_rms_m",
            "rms_3d_before_m", "rms_3d_after_m", "holdout_rms_3d_m", "holdout_kind",  # 3-D: URDF points/poses
            "model_choice",  # URDF robots: {asked, route, reason}
            "prior_class",  # robots with compliance terms: {class, asked, reason, compliance_sigma}
            "correction",  # present only when the nominal robot was kept: {applied: false, statement, reason, tried}
            "residual_unit",  # px for a camera (its *_m residual figures are px); absent: m
            "hand_eye",  # a camera: the hand-eye transform, its stated σ (image jackknife) and the independent-corner σ
            "family", "rms_after_Nm", "holdout_rms_Nm", "condition_number", "model_choice_label")  # dynamics


def _consistent(run_dir: Path, docs: dict[str, dict], doc: dict) -> bool:
    """A stage.json belongs to this run if each input key is the current key of that stage."""
    for dep, key in doc.get("inputs", {}).items():
        if dep == "recording_sha256":
            continue
        if dep not in docs or docs[dep].get("key") != key:
            return False
    return True


def gather(run_dir: Path) -> dict:

    docs: dict[str, dict] = {}
    for s in STAGES:
        d = read_stage(run_dir, s.name)
        if d is not None and _consistent(run_dir, docs, d):
            docs[s.name] = d
    summary: dict = {}
    for d in docs.values():
        for k in HEADLINE:
            if k in d.get("summary", {}):
                summary[k] = d["summary"][k]
    rank = {"pass": 0, "warn": 1, "insufficient": 2, "tolerance_fail": 3, "fail": 4}
    status = "pass"
    for d in docs.values():
        st = d.get("summary", {}).get("status")
        if rank.get(st, 0) > rank[status]:
            status = st
    acc = docs.get("accuracy", {}).get("summary", {})
    if status == "tolerance_fail" or acc.get("status") == "tolerance_fail" and status != "fail":
        status = "fail"  # the calibration does not meet the user's tolerance (--tolerance)
    summary["status"] = status
    if "predicted_point_sigma_rms_m" in summary:  # kept for the expected files; never displayed
        summary["superseded"] = {"predicted_point_sigma_rms_m": "fit covariance at the measurements only; the stated "
                                                                "accuracy is predicted_map_rms_1sigma_m"}
    if acc:  # the accuracy verdict: never a confident answer from thin data
        for k in ("reason", "advice"):
            if acc.get(k):
                summary[f"status_{k}"] = acc[k]
    corr = summary.get("correction")
    if isinstance(corr, dict) and not corr.get("applied", True):  # the status says the robot was not corrected
        from pipeline.identify.correction import line

        summary["status_reason"] = line(corr) + (f"; {summary['status_reason']}" if summary.get("status_reason")
                                                 else "")
        for k in ("map_rms_1sigma_m", "map_max_bound95_m", "new_measurement_rms_3d_m"):
            if k in acc:
                summary[f"predicted_{k}"] = acc[k]
    ingest = docs.get("ingest", {}).get("summary", {})
    warnings = list(ingest.get("warnings", []))
    warnings += list(docs.get("identify", {}).get("summary", {}).get("warnings", []))
    for c in docs.get("validate", {}).get("summary", {}).get("checks", []):
        if c["status"] != "pass":
            warnings.append(f"validate {c['name']} ({c['status']}): {c['message']}")
    physics = docs.get("identify", {}).get("summary", {}).get("physics")
    return {
        "robocal_version": __version__,
        "source": ingest.get("source", {}),
        "summary": summary,
        "warnings": warnings,
        **({"physics": physics} if physics else {}),
        "stages": {n: {"key": d["key"], "params": d.get("params", {}), "summary": d.get("summary", {})}
                   for n, d in docs.items()},
    }
