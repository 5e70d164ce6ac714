"""CI reprocessing: the pipeline over every recording of a folder, in parallel processes,
compared with the expected figures stored beside each recording (`<stem>.expected.json`).

Expected file: ``{"figures": {name: rule}}`` over the keys of results.json's `summary`,
a rule being ``{"equals": v}``, ``{"value": v, "rel_tol": r}`` / ``{"value": v, "abs_tol": a}``,
``{"max": v}`` or ``{"min": v}``.
"""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

COLUMNS = ("recording", "system", "n_measurements", "rms_before_m", "rms_after_m", "holdout_rms_m",
           "n_identifiable", "status", "regressions")


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


def process_one(recording: str, out: str, stages: list[str] | None = None) -> dict:
    """Run the pipeline on one recording (in a worker process); the row of the summary table."""
    from pipeline.errors import RobocalError
    from pipeline.stages.artefacts import read_json
    from pipeline.stages.runner import StageFailed, run_pipeline

    rec, out_p = Path(recording), Path(out)
    row: dict = {"recording": rec.name, "run_dir": str(out_p)}
    try:
        outs = run_pipeline(rec, out_p, stages=stages)
        row["cached_stages"] = sum(o.cached for o in outs)
        row["stages"] = len(outs)
        error = None
    except StageFailed as e:
        error = f"failed: {e}"
    except RobocalError as e:
        error = f"error: {e}"
    except Exception as e:  # noqa: BLE001 — a crash on one recording must not hide the others
        error = f"crash: {type(e).__name__}: {e}"
    summary = read_json(out_p / "results.json")["summary"] if (out_p / "results.json").is_file() else {}
    row.update({k: summary.get(k) for k in COLUMNS if k in summary})
    if error:
        row["status"] = error
    exp_path = rec.with_name(rec.name.removesuffix(".mcap") + ".expected.json")
    if exp_path.is_file():
        row["regressions"] = compare_expected({**summary, **({"status": row["status"]} if error else {})},
                                              read_json(exp_path))
        row["expected"] = exp_path.name
    else:
        row["regressions"] = []
        row["expected"] = None
    row["ok"] = not error and not row["regressions"]
    return row


def reprocess(folder: Path, out: Path, workers: int | None = None, stages: list[str] | None = None) -> list[dict]:
    """Every `*.mcap` of `folder` → `out/<stem>/`; rows in file-name order."""
    recs = sorted(Path(folder).glob("*.mcap"))
    out.mkdir(parents=True, exist_ok=True)
    n = max(1, min(len(recs), workers or os.cpu_count() or 1))
    if not recs:
        return []
    with ProcessPoolExecutor(max_workers=n) as pool:
        futs = [pool.submit(process_one, str(r), str(out / r.stem), stages) for r in recs]
        return [f.result() for f in futs]


def write_summary(rows: list[dict], out: Path) -> None:
    """out/summary.json and out/summary.csv (pyarrow)."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    from pipeline.stages.artefacts import write_json

    write_json(out / "summary.json", {"rows": rows, "ok": all(r["ok"] for r in rows)})
    cols = {c: [r.get(c) if c != "regressions" else "; ".join(r.get(c) or []) for r in rows] for c in COLUMNS}
    cols["ok"] = [r["ok"] for r in rows]
    pcsv.write_csv(pa.table(cols), out / "summary.csv")
