"""Figures of the fleet page as inline SVG (matplotlib object API; deterministic output).  Values are
SI in, mm / deg out."""

from __future__ import annotations

import io
from datetime import datetime, timezone

import numpy as np
from matplotlib import rc_context
from matplotlib.figure import Figure

from pipeline.fleet.history import RobotHistory
from pipeline.report.labels import residual_display

RC = {"svg.fonttype": "none", "svg.hashsalt": "robocal-fleet", "font.size": 8, "axes.titlesize": 8,
      "axes.spines.top": False, "axes.spines.right": False, "axes.grid": True, "grid.alpha": 0.3,
      "legend.fontsize": 7, "legend.frameon": False, "xtick.labelsize": 6, "ytick.labelsize": 6}


def display(unit: str) -> tuple[float, str]:
    """Scale and unit for display of an SI unit."""
    return (1e3, "mm") if unit == "m" else (180 / np.pi, "deg") if unit == "rad" else (1.0, unit)


def dates(t_ns: np.ndarray) -> list[datetime]:
    return [datetime.fromtimestamp(int(t) / 1e9, tz=timezone.utc).replace(tzinfo=None) for t in t_ns]


def _svg(fig: Figure) -> str:
    buf = io.StringIO()
    with rc_context(RC):
        fig.savefig(buf, format="svg", metadata={"Date": None})
    s = buf.getvalue()
    return s[s.index("<svg"):]


def _dates_axis(ax) -> None:
    import matplotlib.dates as mdates

    ax.xaxis.set_major_locator(mdates.AutoDateLocator(minticks=3, maxticks=6))
    ax.xaxis.set_major_formatter(mdates.DateFormatter("%Y-%m"))


def accuracy(h: RobotHistory, tolerance_m: float | None) -> str:
    """Held-out RMS and predicted 1σ tip accuracy per calibration, with the tolerance: mm for length
    residuals; px when every calibration of the robot is a camera run (its figures are px, and a length
    tolerance does not apply)."""
    rows = [r for r in h.usable if r.get("holdout_rms_m") is not None]
    px = bool(rows) and all(r.get("residual_unit") == "px" for r in rows)
    k, unit = residual_display("px" if px else None)
    rows = [r for r in rows if (r.get("residual_unit") == "px") == px]
    tolerance = None if px else tolerance_m
    with rc_context(RC):
        fig = Figure(figsize=(7.5, 2.0), layout="constrained")
        ax = fig.subplots()
        if rows:
            t = dates(np.array([r["campaign_start_ns"] for r in rows]))
            ax.plot(t, [r["holdout_rms_m"] * k for r in rows], "o-", color="#1f77b4", ms=3, label="held-out RMS")
            pp = [(ti, r["predicted_point_sigma_rms_m"] * 1e3) for ti, r in zip(t, rows)
                  if r.get("predicted_point_sigma_rms_m") is not None and not px]
            if pp:
                ax.plot(*zip(*pp), "s--", color="#2ca02c", ms=3, label="predicted tip 1σ (RMS)")
            bad = [(ti, r["holdout_rms_m"] * k) for ti, r in zip(t, rows)
                   if tolerance is not None and r["holdout_rms_m"] > tolerance]
            if bad:
                ax.plot(*zip(*bad), "o", color="#d62728", ms=7, mfc="none", label="above tolerance")
            _dates_axis(ax)
        if tolerance is not None:
            ax.axhline(tolerance * 1e3, color="#d62728", lw=1, ls=":", label=f"tolerance {tolerance * 1e3:g} mm")
        ax.set_ylabel(unit)
        ax.set_ylim(bottom=0)
        ax.legend(loc="upper left", ncols=4)
    return _svg(fig)


def parameters(h: RobotHistory, ncols: int = 5) -> str:
    """Every parameter's estimate (relative to its first calibration) with ±1σ and ±3σ bands; flagged
    steps as red vertical lines, flagged trends as a dashed fitted line."""
    flagged_names = {s["param"] for s in h.steps} | {t["param"] for t in h.trends}
    names = sorted(h.series, key=lambda n: n not in flagged_names)  # flagged first, else model order
    if not names:
        return ""
    nrows = (len(names) + ncols - 1) // ncols
    step_at = {}
    for s in h.steps:
        step_at.setdefault(s["param"], []).append(s)
    trend = {t["param"]: t for t in h.trends}
    with rc_context(RC):
        fig = Figure(figsize=(1.85 * ncols, 1.25 * nrows))
        axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True)
        fig.subplots_adjust(left=0.05, right=0.99, top=0.97, bottom=0.06, wspace=0.45, hspace=0.55)
        for ax in axes.flat[len(names):]:
            ax.set_visible(False)
        for ax, name in zip(axes.flat, names):
            s = h.series[name]
            k, unit = display(s.unit)
            t = dates(s.t_ns)
            y, e = (s.estimate - s.estimate[0]) * k, s.std * k
            ax.fill_between(t, y - 3 * e, y + 3 * e, color="#1f77b4", alpha=0.12, lw=0)
            ax.fill_between(t, y - e, y + e, color="#1f77b4", alpha=0.3, lw=0)
            ax.plot(t, y, "o-", color="#1f77b4", ms=2, lw=0.8)
            flagged = name in step_at or name in trend
            for st in step_at.get(name, []):
                ax.axvline(dates(np.array([st["t_ns"]]))[0], color="#d62728", lw=1.2)
            if name in trend:
                tr = trend[name]
                ty = (s.t_ns - s.t_ns[0]) / 365.25 / 86400e9
                lv = np.asarray(tr["levels"])[np.asarray(tr["segments"])]
                ax.plot(t, (lv + tr["slope_per_year"] * ty - s.estimate[0]) * k, "--", color="#d62728", lw=1.2)
            ax.set_title(f"{name} ({unit})", color="#d62728" if flagged else "black",
                         fontweight="bold" if flagged else "normal")
            _dates_axis(ax)
            ax.tick_params(axis="x", labelrotation=45)
    return _svg(fig)
