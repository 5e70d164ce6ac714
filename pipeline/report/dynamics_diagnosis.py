"""The dynamics diagnosis in report.html: the status, each finding (its parameters with σ, the held-out
torque error without and with it, its confidence), the rejected ones, where the rest is (per joint, velocity
regime, load and time), what the campaign could not see, and what it can tell of the drives' scale
(DIR/diagnose/diagnosis.json of a dynamics run)."""

from __future__ import annotations

from html import escape

from pipeline.report.markup import section, table


def _f(v, fmt=".4f") -> str:
    return "—" if v is None else format(v, fmt)


def render(doc: dict) -> str:
    """The diagnosis section (HTML)."""
    parts = [f"<p><b>{escape(doc['status'])}</b>: {escape(doc['status_reason'])}. Held-out torque RMS (contiguous "
             f"blocks, raw torques) {_f(doc['holdout_rms_before_m'])} → {_f(doc['holdout_rms_after_m'])} N·m pooled.</p>"]
    rows = [[escape(fd["effect"]), escape(fd["location"]),
             escape("; ".join(f"{p['name']} {p['value']:.4g} ± {p['std']:.2g} {p['unit']}" for p in fd["parameters"])),
             _f(fd["evidence"]["cv_rms_before_m"]), _f(fd["evidence"]["cv_rms_after_m"]), escape(fd["confidence"]),
             escape(fd.get("note", ""))] for fd in doc["findings"]]
    rows += [[escape(fd["effect"]), escape(fd["location"]), "", _f(fd["evidence"]["cv_rms_before_m"]),
              _f(fd["evidence"]["cv_rms_after_m"]), "rejected", escape(fd.get("note", ""))]
             for fd in doc["rejected_findings"]]
    if rows:
        parts.append(table(["effect", "where", "parameters (1σ)", "held-out without N·m", "held-out with N·m",
                            "confidence", "note"], rows, {3, 4}))
    where = doc.get("unexplained_where") or []
    if where:
        parts.append("<p>Structure no library term explains: " + "; ".join(
            f"{escape(w['variable'])} (p = {w['p_value']:.2g}): {escape(w['advice'])}" for w in where) + "</p>")
    loc = [[escape(r["joint"]), escape(r["by"]), escape(r["regime"]), f"{100 * r['share']:.0f} %",
            _f(r["rms_before"]), _f(r["rms_after"])] for r in doc.get("located", [])]
    if loc:
        parts.append("<p>Held-out torque RMS by joint and regime (N·m):</p>" +
                     table(["joint", "by", "regime", "share", "before", "after"], loc, {3, 4, 5}))
    nid = [[escape(n["effect"]), escape(n["location"]), escape(n["reason"])] for n in doc["not_identifiable"]]
    if nid:
        parts.append("<p>What this recording cannot see:</p>" + table(["effect", "where", "why"], nid, set()))
    ds = doc.get("drive_scale") or {}
    if ds.get("per_joint"):
        parts.append("<p>Drive scales (effort → torque constants): " + "; ".join(
            f"{escape(d['joint'])}: " + (f"a relative error from {d['min_detectable_relative']:.1%} is detectable"
                                         if d["identifiable"] else "not identifiable") +
            (f", found {d['found']['value']:+.3f} ± {d['found']['std']:.3f}" if d.get("found") else "")
            for d in ds["per_joint"]) + f". A common scale: {escape(ds['common_scale'])}.</p>")
    return section("diagnosis", "Diagnosis: what the rigid-body model leaves out", "".join(parts))
