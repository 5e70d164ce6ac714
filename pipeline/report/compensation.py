"""Report section "Compensation": shown when `robocal compensate` wrote RUN_DIR/compensation/."""

from __future__ import annotations

import json
from html import escape
from pathlib import Path

import numpy as np

from pipeline.report.markup import section as _section
from pipeline.report.markup import table as _table

FILE = Path("compensation") / "compensation.json"
SHOWN_ROWS = 200


def load(run_dir: Path) -> dict | None:
    p = Path(run_dir) / FILE
    return json.loads(p.read_text()) if p.is_file() else None


def section(run_dir: Path) -> str | None:
    """HTML of the section, or None when no program was compensated."""
    doc = load(run_dir)
    if doc is None:
        return None
    rows = doc["rows"]
    sig = np.array([r["predicted_sigma_m"] for r in rows])
    counts = ", ".join(f"{v} {escape(k)}" for k, v in doc["status_counts"].items())
    rms, corr = doc.get("predicted_sigma_rms_m"), doc.get("correction_median_m")
    rms_s = "—" if rms is None else f"{rms * 1e3:.4f} mm"
    b95 = doc.get("predicted_rms_bound95_m")
    b95_s = "—" if b95 is None else f"{b95 * 1e3:.4f} mm"
    corr_s = "—" if corr is None else f"{corr * 1e3:.3f} mm"
    head = (f"<p>{doc['n_targets']} targets of <code>{escape(doc['targets'])}</code> compensated into "
            f"<code>{escape(doc['program'])}</code>: {counts}. <b>Predicted accuracy (95 %)</b>: this calibration's "
            f"RMS 3-D tool-point error over the program ≤ {b95_s}. Predicted 1σ error of the calibrated model at the "
            f"compensated joints (from the parameter covariance; its RMS expected over calibrations, one calibration spreads "
            f"around it): RMS {rms_s}, max {np.nanmax(sig) * 1e3:.4f} mm; median correction {corr_s}.</p>")
    table = _table(["row", "status", "predicted σ (mm)", "correction (mm)"],
                   [[str(r["row"]), escape(r["status"]), f"{r['predicted_sigma_m'] * 1e3:.4f}",
                     f"{r['correction_m'] * 1e3:.3f}"] for r in rows[:SHOWN_ROWS]], numeric={0, 2, 3})
    more = f"<p>First {SHOWN_ROWS} of {len(rows)} rows; all are in the program CSV.</p>" if len(rows) > SHOWN_ROWS else ""
    return _section("compensation", "Compensation", head + table + more)
