"""CI reprocessing: the regression rules of the expected figures stored beside each recording
(`<stem>.expected.json`), and the end-of-run summary files.  The run itself (discovery, Dask,
the streamed Parquet dataset, resume) is `pipeline.fleet.engine`.

Expected file: ``{"figures": {name: rule}}`` over the keys of results.json's `summary`,
a rule being ``{"equals": v}``, ``{"value": v, "rel_tol": r}`` / ``{"value": v, "abs_tol": a}``,
``{"max": v}`` or ``{"min": v}``.
"""

from __future__ import annotations

from pathlib import Path

COLUMNS = ("recording", "robot_id", "system", "n_measurements", "rms_before_m", "rms_after_m", "holdout_rms_m",
           "n_identifiable", "status", "error", "regressions")


def check_figure(name: str, rule: dict, actual) -> str | None:
    """None if `actual` satisfies `rule`, else a one-line reason."""
    if actual is None:
        return f"{name}: missing from the results"
    if "equals" in rule:
        return None if actual == rule["equals"] else f"{name} = {actual!r}, expected {rule['equals']!r}"
    if "value" in rule:
        v = float(rule["value"])
        tol = float(rule["abs_tol"]) if "abs_tol" in rule else abs(v) * float(rule.get("rel_tol", 0.0))
        return None if abs(float(actual) - v) <= tol else f"{name} = {actual:.6g}, expected {v:.6g} ± {tol:.3g}"
    if "max" in rule and float(actual) > float(rule["max"]):
        return f"{name} = {actual:.6g} above the maximum {rule['max']:.6g}"
    if "min" in rule and float(actual) < float(rule["min"]):
        return f"{name} = {actual:.6g} below the minimum {rule['min']:.6g}"
    return None


def compare_expected(summary: dict, expected: dict) -> list[str]:
    """Every expected figure that the summary misses."""
    return [r for name, rule in expected.get("figures", {}).items()
            if (r := check_figure(name, rule, summary.get(name))) is not None]


def write_summary(rows: list[dict], out: Path) -> None:
    """out/summary.json and out/summary.csv (pyarrow), written at the end of a run (the rows without
    their parameter lists: those are in the Parquet dataset out/results/)."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    from pipeline.stages.artefacts import write_json

    brief = [{k: v for k, v in r.items() if k != "parameters"} for r in rows]
    write_json(out / "summary.json", {"rows": brief, "ok": all(r["ok"] for r in rows)})
    cols = {c: [r.get(c) if c != "regressions" else "; ".join(r.get(c) or []) for r in rows] for c in COLUMNS}
    cols["ok"] = [r["ok"] for r in rows]
    pcsv.write_csv(pa.table(cols), out / "summary.csv")
