"""Plots of the report as inline SVG strings (matplotlib, object API: no pyplot, no display).

Each function takes figure data (SI) and returns one ``<svg>…</svg>`` string in display units
(mm, deg).  Output is deterministic: no date in the metadata and a fixed id salt.
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib import rc_context
from matplotlib.figure import Figure

from pipeline.report.figures import ResidualSeries
from pipeline.report.labels import joint_scale, plain_log_ticks

MM = 1e3
DEG = 180.0 / np.pi
RC = {"svg.fonttype": "none", "svg.hashsalt": "robocal", "font.size": 9, "axes.titlesize": 10,
      "axes.spines.top": False, "axes.spines.right": False, "axes.grid": True, "grid.alpha": 0.3,
      "legend.fontsize": 8, "legend.frameon": False,
      "text.parse_math": False}  # recording strings (face ids, topics) are shown as written: `$` is not mathtext
COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
          "#bcbd22", "#17becf"]


RASTER_POINTS = 3000  # an axes whose scatters and lines hold more points than this draws them as an image
RASTER_DPI = 150


def _raster_large(fig: Figure) -> bool:
    """Rasterise the collections and lines of every (2-D) axes of `fig` that hold more than RASTER_POINTS
    points together (axes, labels and text stay vector): thousands of SVG markers (a camera's corners)
    cost minutes to write and to display."""
    big = False
    for ax in fig.axes:
        if ax.name == "3d":  # matplotlib cannot rasterise 3-D collections
            continue
        arts = [*ax.collections, *ax.lines]
        n = sum(len(a.get_xydata()) if hasattr(a, "get_xydata") else len(a.get_offsets()) for a in arts)
        if n > RASTER_POINTS:
            for a in arts:
                a.set_rasterized(True)
            big = True
    return big


def _svg(fig: Figure) -> str:
    """`fig` as an SVG string, drawn once: the SVG canvas's own print runs the constrained layout inside its
    one draw, where `Figure.savefig` first draws the whole figure unrendered for the layout, then again (the
    same SVG, ≈ 25 % less CPU)."""
    from matplotlib.backends.backend_svg import FigureCanvasSVG

    buf = io.StringIO()
    with rc_context(RC):
        if _raster_large(fig):
            fig.set_dpi(RASTER_DPI)  # the resolution of the rasterised collections
        FigureCanvasSVG(fig).print_svg(buf, metadata={"Date": None})
    s = buf.getvalue()
    return s[s.index("<svg"):]


def _fig(w: float, h: float, nrows: int = 1, ncols: int = 1, **kw) -> tuple[Figure, np.ndarray]:
    with rc_context(RC):
        fig = Figure(figsize=(w, h), layout="constrained")
        axes = fig.subplots(nrows, ncols, squeeze=False, **kw)
    return fig, axes


def hist_bins(v: np.ndarray, n: int) -> tuple[np.ndarray, int | np.ndarray]:
    """(finite values of `v`, bins) for a histogram: `n` equal bins, or one bin spanning the values
    when their range is too narrow (a few equal measurements) or too wide for `n` finite-sized bins."""
    v = np.asarray(v, float).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0:
        return v, n
    try:
        np.histogram_bin_edges(v, bins=n)
        return v, n
    except ValueError:
        lo, hi = float(v.min()), float(v.max())
        return v, (np.array([lo, hi]) if lo < hi else 1)


def group_colors(groups: Sequence[str]) -> dict[str, str]:
    return {g: COLORS[i % len(COLORS)] for i, g in enumerate(sorted(set(groups)))}


def _scatter_groups(a, x: np.ndarray, y: np.ndarray, group: np.ndarray, colors: dict[str, str], size: float,
                    hollow: bool = False, lw: float = 0.0) -> None:
    """Every point as a marker coloured by its group (`size` a scatter's area, pt²): one marker line per
    group, which Agg draws in C — a scatter with per-point colours is drawn path by path in Python (a
    camera's ten thousand corners: seconds per figure)."""
    g = np.asarray(group).astype(str)
    ms = float(np.sqrt(size))
    for k, c in colors.items():
        m = g == str(k)
        if not m.any():
            continue
        if hollow:
            a.plot(x[m], y[m], ls="", marker="o", ms=ms, mfc="none", mec=c, mew=lw)
        else:
            a.plot(x[m], y[m], ls="", marker="o", ms=ms, color=c, mew=0)


def _group_handles(colors: dict[str, str]) -> list:
    """Legend entries of `_scatter_groups`' groups."""
    from matplotlib.lines import Line2D

    return [Line2D([], [], ls="", marker="o", markersize=4, color=c, label=g) for g, c in colors.items()]


def residuals_by_group(s: ResidualSeries) -> str:
    """Strip plot per face/channel: residuals before, after and held out (mm)."""
    groups = sorted(set(s.group))
    with rc_context(RC):
        fig, ax = _fig(9.5, 3.2, 1, 2)
        rng = np.random.default_rng(0)
        for a, (title, sets) in zip(ax[0], [("before calibration", [("before", s.before, "#d62728")]),
                                            ("after calibration", [("after", s.after, "#2ca02c"),
                                                                   ("held out", s.holdout, "#ff7f0e")])]):
            for gi, g in enumerate(groups):
                m = s.group == g
                for si, (label, y, c) in enumerate(sets):
                    yy = y[m] * s.scale
                    ok = np.isfinite(yy)
                    off = (si - (len(sets) - 1) / 2) * 0.25
                    a.scatter(gi + off + rng.uniform(-0.08, 0.08, ok.sum()), yy[ok], s=10, color=c, alpha=0.75,
                              label=label if gi == 0 else None, linewidths=0)
            a.axhline(0, color="k", lw=0.6)
            a.set_xticks(range(len(groups)), groups, rotation=30, ha="right")
            a.set_title(title)
            a.set_ylabel(f"residual ({s.unit})")
            a.legend(loc="upper right")
    return _svg(fig)


def residuals_vs_time(s: ResidualSeries) -> str:
    """Residuals against time since the first measurement, per face/channel: before; after and held out."""
    colors = group_colors(s.group)
    with rc_context(RC):
        fig, ax = _fig(9.5, 4.6, 2, 1, sharex=True)
        _scatter_groups(ax[0, 0], s.t_s, s.before * s.scale, s.group, colors, 12)
        _scatter_groups(ax[1, 0], s.t_s, s.after * s.scale, s.group, colors, 12)
        _scatter_groups(ax[1, 0], s.t_s, s.holdout * s.scale, s.group, colors, 14, hollow=True, lw=0.7)
        rej = ~s.used
        if rej.any():
            ax[1, 0].scatter(s.t_s[rej], s.after[rej] * s.scale, s=30, marker="x", color="k", label="rejected outlier")
            ax[1, 0].legend(loc="upper right")
        ax[0, 0].set_title("before calibration")
        ax[1, 0].set_title("after calibration (filled) and held out (hollow)")
        for a in ax[:, 0]:
            a.axhline(0, color="k", lw=0.6)
            a.set_ylabel(f"residual ({s.unit})")
        ax[1, 0].set_xlabel(s.time_label)
        ax[0, 0].legend(handles=_group_handles(colors), loc="center left", bbox_to_anchor=(1.0, 0.0),
                        title=s.group_title)
    return _svg(fig)


def residuals_vs_joints(s: ResidualSeries) -> str:
    """Residuals after calibration (filled) and held out (hollow) against each joint angle (deg)."""
    joints = list(s.joints)
    colors = group_colors(s.group)
    ncols = 3 if len(joints) > 4 else max(len(joints), 1)
    nrows = max(int(np.ceil(len(joints) / ncols)), 1)
    with rc_context(RC):
        fig, ax = _fig(9.5, 2.5 * nrows + 0.4, nrows, ncols, sharey=True)
        for i, a in enumerate(ax.ravel()):
            if i >= len(joints):
                a.set_visible(False)
                continue
            scale, unit = joint_scale(joints[i], s.prismatic)  # deg; a prismatic joint's m in mm
            q = s.joints[joints[i]] * scale
            _scatter_groups(a, q, s.after * s.scale, s.group, colors, 10)
            _scatter_groups(a, q, s.holdout * s.scale, s.group, colors, 12, hollow=True, lw=0.6)
            a.axhline(0, color="k", lw=0.6)
            a.set_xlabel(f"{joints[i]} ({unit})")
            if i % ncols == 0:
                a.set_ylabel(f"residual after ({s.unit})")
        if joints:
            fig.legend(handles=_group_handles(colors), loc="outside right center", title=s.group_title)
    return _svg(fig)


def singular_values(s: np.ndarray) -> str:
    """Singular values of the scaled identification Jacobian (log scale)."""
    with rc_context(RC):
        fig, ax = _fig(6.0, 3.0)
        a = ax[0, 0]
        k = np.arange(1, s.size + 1)
        a.bar(k, s, color="#1f77b4", width=0.7)
        a.set_yscale("log")
        plain_log_ticks(a)
        a.set_xlabel("index")
        a.set_ylabel("singular value (scaled Jacobian)")
        if s.size and s[-1] > 0:
            a.set_title(f"condition number {s[0] / s[-1]:.3g}")
    return _svg(fig)


def correlation(names: list[str], c: np.ndarray) -> str:
    """Parameter correlation matrix (free parameters), −1…1."""
    n = len(names)
    size = min(max(4.0, 0.22 * n + 2.0), 10.0)
    with rc_context(RC | {"axes.grid": False}):
        fig, ax = _fig(size + 1.0, size)
        a = ax[0, 0]
        im = a.imshow(c, cmap="RdBu_r", vmin=-1, vmax=1, interpolation="nearest")
        fs = 7 if n <= 30 else 5
        a.set_xticks(range(n), names, rotation=90, fontsize=fs)
        a.set_yticks(range(n), names, fontsize=fs)
        fig.colorbar(im, ax=a, shrink=0.8, label="correlation")
    return _svg(fig)


def solver_history(history: Sequence[float]) -> str:
    """Cost (RMS, mm) of each solver evaluation."""
    with rc_context(RC):
        fig, ax = _fig(6.0, 2.8)
        a = ax[0, 0]
        h = np.asarray(history, float) * MM
        a.plot(np.arange(h.size), h, marker="o", ms=3, color="#5a5ac8")
        if h.size and np.all(h > 0):
            a.set_yscale("log")
            plain_log_ticks(a)
        a.set_xlabel("evaluation")
        a.set_ylabel("RMS residual (mm)")
    return _svg(fig)


def point_sigma(t_s: np.ndarray, sigma_m: np.ndarray) -> str:
    """Predicted 3-D 1σ accuracy of the calibrated model's point at each measurement (mm)."""
    with rc_context(RC):
        fig, ax = _fig(6.0, 2.8)
        a = ax[0, 0]
        v, bins = hist_bins(np.asarray(sigma_m, float) * MM, 20)
        a.hist(v, bins=bins, color="#17becf")
        a.set_xlabel("predicted point accuracy, 1σ (mm)")
        a.set_ylabel("measurements")
    return _svg(fig)


def xy_series(x: np.ndarray, series: Mapping[str, np.ndarray], x_label: str, y_label: str,
              title: str = "", y_scale: float = 1.0) -> str:
    """Generic scatter of several named series against one variable (diagnosis plots)."""
    with rc_context(RC):
        fig, ax = _fig(6.4, 3.0)
        a = ax[0, 0]
        palette = ["#d62728", "#2ca02c", "#1f77b4", "#ff7f0e", "#9467bd"]
        x = np.asarray(x, float)
        levels = np.unique(x[np.isfinite(x)])
        categorical = 0 < levels.size <= 5  # e.g. a motion sign −1/0/+1: spread the series side by side
        step = float(np.min(np.diff(levels))) if levels.size > 1 else 1.0
        rng = np.random.default_rng(0)
        for i, (name, y) in enumerate(series.items()):
            xi = x
            if categorical:
                xi = x + step * ((i - (len(series) - 1) / 2) * 0.18 + rng.uniform(-0.05, 0.05, x.size))
            a.scatter(xi, np.asarray(y, float) * y_scale, s=10, color=palette[i % len(palette)], label=name,
                      alpha=0.8, linewidths=0)
        if categorical:
            a.set_xticks(levels, [f"{v:g}" for v in levels])
        a.axhline(0, color="k", lw=0.6)
        a.set_xlabel(x_label)
        a.set_ylabel(y_label)
        if title:
            a.set_title(title)
        a.legend()
    return _svg(fig)


def bars(labels: Sequence[str], values: Sequence[float], y_label: str, title: str = "") -> str:
    """Simple bar chart (e.g. held-out RMS before/after the diagnosis)."""
    with rc_context(RC):
        fig, ax = _fig(4.0, 2.6)
        a = ax[0, 0]
        a.bar(list(labels), list(values), color=["#d62728", "#2ca02c", "#1f77b4"][: len(labels)], width=0.55)
        a.set_ylabel(y_label)
        if title:
            a.set_title(title)
    return _svg(fig)


def error_norms(recordings: Sequence[str], norms: Sequence[np.ndarray], kinds: Sequence[np.ndarray],
                y_label: str, scale: float = MM) -> str:
    """Each measurement's error (m, shown in mm; a camera's px with `scale` 1) of each evaluated recording,
    one column per recording, coloured by its kind (e.g. its posture group relative to the training postures)."""
    with rc_context(RC):
        fig, ax = _fig(6.4, 3.0)
        a = ax[0, 0]
        colors = group_colors([str(k) for ks in kinds for k in ks])
        rng = np.random.default_rng(0)
        seen = set()
        for i, (v, ks) in enumerate(zip(norms, kinds)):
            v, ks = np.asarray(v, float), np.asarray(ks).astype(str)
            for k in sorted(set(ks)):
                s = ks == k
                a.scatter(i + rng.uniform(-0.25, 0.25, int(s.sum())), v[s] * scale, s=10, color=colors[k],
                          label=None if k in seen or not k else k, alpha=0.8, linewidths=0)
                seen.add(k)
        a.set_xticks(range(len(recordings)), list(recordings), rotation=15, ha="right")
        a.set_ylabel(y_label)
        a.set_ylim(bottom=0)
        if any(seen - {""}):
            a.legend()
    return _svg(fig)
