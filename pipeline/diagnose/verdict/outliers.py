"""Records, not physics: the influence screen around a diagnosis (`checks`).

Before the diagnosis: a record whose derived approach speed is beyond any touch search
(`checks.implausible_speed`) or, when the recording has each contact's search command, off the
commanded search speed (`checks.speed_mismatch`) is set aside and named.  After a first diagnosis: a record
whose residual is far off the fitted model — the geometry and the effects found, not the geometry alone
(externally studentized, Bonferroni at the family α: `checks.studentized_outliers`; a record the geometry cannot
fit but a library effect can is that effect's evidence) — is set aside and named, and the diagnosis run again
without it.  After it: a finding that is no longer significant with one or two records left out
(`checks.carried_by`, computed inside the diagnosis) is reported as an outlier of those records
and the diagnosis is run again without them (once; a finding still carried by a few records
after that is rejected); the status reason says so (the effect is not shown to be absent, only to rest on
those records: as often noise as physics, so the status itself is not changed).  Every record set aside is listed in `outlier_records` with the
reason.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from pipeline.diagnose.verdict import checks
from pipeline.identify.least_squares import Fit, FitOptions, fit
from pipeline.identify.model import take


def _entry(table, i: int, r: np.ndarray, reason: str) -> dict:
    rec = table.get("record")
    return {"record": int(np.asarray(rec)[i]) if rec is not None else int(i),
            "face": str(np.asarray(table["face"])[i]) if "face" in table else None,
            "residual_m": float(r[i]), "reason": reason}


def screened(run: Callable[[dict, Fit | None, np.ndarray | None], dict], model, table: dict, *,
             x0: np.ndarray | None, geometry_fit: Fit | None, alpha: float,
             speed: Callable[[np.ndarray, dict], np.ndarray] | None = None, passes: int = 2) -> dict:
    """`run(table, geometry_fit, x0)` → diagnosis document (with its `_carried` map), around the
    screen of the module docstring; adds `outlier_records` [{record, face, residual_m, reason}]."""
    f = geometry_fit or fit(model, table, FitOptions(x0=x0))
    n = f.residuals_after.shape[0]
    r = f.residuals_after[:, 0]
    out, bad = [], []
    if speed is not None:
        sp = speed(f.x, table)
        for i in checks.implausible_speed(sp):
            bad.append(int(i))
            out.append(_entry(table, i, r, f"derived approach speed {sp[i]:.3g} m/s is beyond any touch search "
                                           f"(> {checks.MAX_SEARCH_SPEED_M_S} m/s): a fault of this record"))
        if "search_speed_m_s" in table:  # the recorded search command: the derived speed must match it
            cmd = np.asarray(table["search_speed_m_s"], float)
            for i in checks.speed_mismatch(sp, cmd):
                if int(i) not in bad:
                    bad.append(int(i))
                    out.append(_entry(table, i, r, f"derived approach speed {sp[i]:.3g} m/s is not the commanded "
                                                   f"search speed {cmd[i]:.3g} m/s (beyond ×{checks.SPEED_FACTOR:g}): "
                                                   f"a fault of this record's encoder stream or latch"))
    def sub(rows_out):
        keep = np.setdiff1d(np.arange(n), rows_out)
        return keep, (take(table, np.isin(np.arange(n), keep)) if len(rows_out) else table)

    # gross errors are judged against the model the data ask for — the geometry and the effects found — not the
    # geometry alone: a record the geometry cannot fit but a library effect can is that effect's evidence
    keep, tab = sub(bad)
    first = run(tab, None if bad else f, f.x)
    A, r_fin = first.pop("_final")
    flagged = [(int(keep[i]), t) for i, t in checks.studentized_outliers(A, r_fin, alpha)]
    if flagged and hasattr(model, "points") and "face" in table:  # a local structure is not an outlier
        t_all = np.zeros(n)
        t_all[keep] = checks.studentized(A, r_fin)
        tip = model.points(f.x, table)[0]
        flagged = [(i, t) for i, t in flagged
                   if not checks.has_like_neighbours(i, tip, np.asarray(table["face"]).astype(str), t_all)]
    for i, t in flagged:
        if i not in bad:
            bad.append(i)
            out.append(_entry(table, i, r, f"{t:+.1f} studentized σ off the fitted model (geometry and the effects "
                                           f"found; beyond the Bonferroni bound at α = {alpha:g}): a bad record, "
                                           "not physics"))
    for attempt in range(passes + 1):
        if attempt or flagged:
            keep, tab = sub(bad)
            doc = run(tab, None if bad else f, f.x)
            doc.pop("_final", None)
        else:
            doc = first
        carried = doc.pop("_carried", {})
        if not carried:
            break
        if attempt == passes:  # still carried by a few records: not reported as found
            hit = [fd for fd in doc["findings"] if f"{fd['effect']}@{fd['location']}" in carried]
            doc["findings"] = [fd for fd in doc["findings"] if fd not in hit]
            doc["rejected_findings"] = doc.get("rejected_findings", []) + [
                {**fd, "confidence": "rejected", "note": "carried by one or two records"} for fd in hit]
            break
        for label, rows in carried.items():
            for q in rows:
                i = int(keep[q])
                if i not in bad:
                    bad.append(i)
                    out.append(_entry(table, i, r, f"the finding {label} rests on this record (not significant "
                                                   f"without it): set aside, the finding is not reported"))
    doc["outlier_records"] = out
    named = {(fd["effect"], fd["location"].split(" (")[0]) for fd in doc["findings"]}
    for e in doc.get("unseen", []):  # a finding dropped above is not found
        e["found"] = (e["effect"], e["location"].split(" (")[0]) in named
    rest = sorted({label for label, _ in carried_labels(out)})
    if rest:  # said beside the status (a finding of one or two records is as often noise as physics)
        recs = sorted({rec for _, rec in carried_labels(out)})
        doc["status_reason"] += (f"; {', '.join(rest)} rested on record(s) {', '.join(map(str, recs))} alone and is "
                                 "not reported (remeasure those poses to tell a bad record from an effect)")
    return doc


def carried_labels(out: list[dict]) -> list[tuple[str, int]]:
    """(finding label, record) of the records set aside because a finding rested on them."""
    pre, post = "the finding ", " rests on this record"
    return [(o["reason"][len(pre):o["reason"].index(post)], o["record"]) for o in out
            if o["reason"].startswith(pre) and post in o["reason"]]
