"""The report's camera section (runs of a ``measure: camera`` recording): reprojection residuals
per image, residual vectors over the image plane, the corners' coverage of the sensor and the
per-corner outliers — all in px (u right, v down, the top-left pixel's centre at (0, 0)).

`camera_figures` is pure (run artefacts in, arrays and rows out); `section` renders them (HTML
and inline SVG).  A corner is an outlier when the fit rejected it, or when its residual after
calibration exceeds `OUTLIER_SIGMAS` robust σ (1.4826·MAD of the used corners' residual
components).
"""

from __future__ import annotations

from dataclasses import dataclass
from html import escape

import numpy as np
from matplotlib import rc_context

from pipeline.report.artefacts import residual_matrix
from pipeline.report.markup import figure, section as _section, table
from pipeline.report.plots import RC, _fig, _svg

OUTLIER_SIGMAS = 5.0
MAX_ARROWS = 2000  # more used corners than this: the quiver draws cell means (`field`)
GRID = (8, 6)  # coverage cells across the width and the height of the image


@dataclass
class CameraFigures:
    """Per corner: image index (n,), label (n,), corner id (n,), detected pixel (n,2) px, residual
    after calibration (n,2) px, held out (n,2) px, used (n,); the image size (w, h) px."""

    image: np.ndarray
    label: np.ndarray
    corner: np.ndarray
    pixel: np.ndarray
    after: np.ndarray
    holdout: np.ndarray
    used: np.ndarray
    size: tuple[int, int]

    def per_image(self) -> list[dict]:
        """One row per image: label, corners, corners used, RMS after and held out, max |r| (px)."""
        out = []
        for i in np.unique(self.image):
            m = self.image == i
            u = m & self.used
            norm = np.linalg.norm(self.after[m], axis=1)
            out.append({"image": int(i), "label": str(self.label[m][0]), "corners": int(m.sum()), "used": int(u.sum()),
                        "rms_after_px": _rms(self.after[u]), "rms_holdout_px": _rms(self.holdout[u]),
                        "max_after_px": float(norm.max()) if norm.size else float("nan")})
        return out

    def coverage(self) -> np.ndarray:
        """Corners per cell of a `GRID` over the image (rows: v, columns: u)."""
        w, h = self.size
        H, _, _ = np.histogram2d(self.pixel[:, 1], self.pixel[:, 0], bins=(GRID[1], GRID[0]), range=[[0, h], [0, w]])
        return H

    def outliers(self) -> list[dict]:
        """Rejected corners and corners beyond `OUTLIER_SIGMAS` robust σ, largest first."""
        r = self.after[self.used].ravel()
        s = 1.4826 * float(np.median(np.abs(r - np.median(r)))) if r.size else 0.0
        norm = np.linalg.norm(self.after, axis=1)
        big = ~self.used | (np.abs(self.after).max(axis=1) > OUTLIER_SIGMAS * s if s > 0 else False)
        rows = [{"label": str(self.label[j]), "corner": int(self.corner[j]), "u_px": float(self.pixel[j, 0]),
                 "v_px": float(self.pixel[j, 1]), "du_px": float(self.after[j, 0]), "dv_px": float(self.after[j, 1]),
                 "norm_px": float(norm[j]), "why": "rejected by the fit" if not self.used[j] else
                 f"> {OUTLIER_SIGMAS:g} robust σ ({s:.3g} px)"} for j in np.flatnonzero(big)]
        return sorted(rows, key=lambda d: -d["norm_px"])


def _px(v: float) -> str:
    return f"{v:.4f}" if np.isfinite(v) else "–"


def _rms(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(r)))) if np.size(r) else float("nan")


def camera_figures(art) -> CameraFigures | None:
    """The camera figures of a run, or None when the run is not of a camera recording."""
    camp = art.metadata.get("robocal.campaign") or {}
    meas = art.measurements
    if camp.get("measure") != "camera" or meas is None or "pixel" not in meas:
        return None
    res = art.residuals
    after, hold = residual_matrix(res, "after"), residual_matrix(res, "holdout")
    if after.shape[1] != 2:
        return None
    idx = {int(r): i for i, r in enumerate(np.asarray(meas["record"]))}
    rows = np.array([idx[int(r)] for r in np.asarray(res["record"])])
    size = camp.get("image_size") or [640, 480]
    label = np.asarray(meas.get("label", meas["image"]), object)[rows]
    return CameraFigures(np.asarray(meas["image"])[rows], label, np.asarray(meas["corner"])[rows],
                         np.asarray(meas["pixel"], float)[rows], after,
                         hold if hold.shape == after.shape else np.full_like(after, np.nan), art.used,
                         (int(size[0]), int(size[1])))


def per_image_bars(rows: list[dict]) -> str:
    """Bars: reprojection RMS after calibration and held out per image (px)."""
    x = np.arange(len(rows))
    with rc_context(RC):
        fig, ax = _fig(9.5, 3.0)
        a = ax[0, 0]
        a.bar(x - 0.2, [r["rms_after_px"] for r in rows], 0.4, color="#2ca02c", label="after calibration")
        a.bar(x + 0.2, [r["rms_holdout_px"] for r in rows], 0.4, color="#ff7f0e", label="held out")
        a.set_xticks(x, [r["label"] for r in rows], rotation=45, ha="right", fontsize=7)
        a.set_ylabel("reprojection RMS (px)")
        a.legend(loc="upper right")
    return _svg(fig)


def _image_axes(a, size: tuple[int, int]) -> None:
    w, h = size
    a.set_xlim(0, w)
    a.set_ylim(h, 0)  # v down, as in the image
    a.set_aspect("equal")
    a.set_xlabel("u (px)")
    a.set_ylabel("v (px)")
    a.add_patch(_rect(w, h))


def _rect(w: float, h: float):
    from matplotlib.patches import Rectangle

    return Rectangle((0, 0), w, h, fill=False, lw=0.8, color="k")


def field(f: CameraFigures) -> tuple[np.ndarray, np.ndarray, str]:
    """The vectors the quiver draws: every used corner's residual (at most `MAX_ARROWS` corners),
    else the mean residual of the used corners in each cell of a grid of ≈ 40 px cells; (positions
    (m,2) px, vectors (m,2) px, what they are)."""
    u = f.used
    if u.sum() <= MAX_ARROWS:
        return f.pixel[u], f.after[u], "each corner's residual"
    w, h = f.size
    nx, ny = max(int(round(w / 40)), 1), max(int(round(h / 40)), 1)
    ix = np.clip((f.pixel[u, 0] / w * nx).astype(int), 0, nx - 1)
    iy = np.clip((f.pixel[u, 1] / h * ny).astype(int), 0, ny - 1)
    cell = iy * nx + ix
    n = np.bincount(cell, minlength=nx * ny)
    keep = np.flatnonzero(n)
    mean = np.stack([np.bincount(cell, f.after[u, c], nx * ny) for c in (0, 1)], 1)[keep] / n[keep, None]
    at = np.stack([np.bincount(cell, f.pixel[u, c], nx * ny) for c in (0, 1)], 1)[keep] / n[keep, None]
    return at, mean, f"the mean residual of the corners in each {w / nx:.0f}×{h / ny:.0f} px cell"


def quiver(f: CameraFigures) -> tuple[str, float, str]:
    """Residual vectors (after calibration) over the image (`field`); (svg, the magnification: px
    drawn per px of residual, what the arrows are)."""
    at, vec, what = field(f)
    norm = np.linalg.norm(vec, axis=1)
    ref = float(np.percentile(norm, 95)) if norm.size else 0.0
    gain = 0.04 * f.size[0] / ref if ref > 0 else 1.0  # the 95th percentile drawn 4 % of the width long
    with rc_context(RC):
        fig, ax = _fig(7.0, 7.0 * f.size[1] / f.size[0] + 0.6)
        a = ax[0, 0]
        u = f.used
        a.quiver(at[:, 0], at[:, 1], vec[:, 0] * gain, vec[:, 1] * gain, angles="xy",
                 scale_units="xy", scale=1, width=0.0025, color="#1f77b4")
        if (~u).any():
            a.scatter(f.pixel[~u, 0], f.pixel[~u, 1], marker="x", color="#d62728", s=25, label="rejected corner")
            a.legend(loc="upper right")
        _image_axes(a, f.size)
        a.set_title(f"residual after calibration, drawn ×{gain:.3g}")
    return _svg(fig), gain, what


def coverage_plot(f: CameraFigures) -> str:
    """Detected corners over the sensor (points, one colour per image) on the corner count per cell (heat)."""
    w, h = f.size
    with rc_context(RC):
        fig, ax = _fig(7.0, 7.0 * h / w + 0.6)
        a = ax[0, 0]
        im = a.imshow(f.coverage(), extent=(0, w, h, 0), cmap="Greys", alpha=0.6, interpolation="nearest")
        fig.colorbar(im, ax=a, label="corners per cell", shrink=0.8)
        a.scatter(f.pixel[:, 0], f.pixel[:, 1], c=f.image, cmap="tab20", s=4, linewidths=0)
        _image_axes(a, f.size)
        a.set_title(f"detected corners of {len(np.unique(f.image))} images")
    return _svg(fig)


def section(art) -> str:
    """The camera section's HTML, or "" for a run that is not of a camera recording."""
    f = camera_figures(art)
    if f is None:
        return ""
    rows = f.per_image()
    html = ('<p class="note">Reprojection residual = projected − detected corner, in px (u right, v down). '
            "Held out: predicted by a fit that did not see the image.</p>")
    html += table(["image", "corners", "used", "RMS after (px)", "RMS held out (px)", "max |r| after (px)"],
                  [[escape(r["label"]), str(r["corners"]), str(r["used"]), _px(r["rms_after_px"]),
                    _px(r["rms_holdout_px"]), _px(r["max_after_px"])] for r in rows], {1, 2, 3, 4, 5})
    html += figure(per_image_bars(rows), "Reprojection RMS per image after calibration and held out (px).",
                   "fig-camera-images")
    svg, gain, what = quiver(f)
    html += figure(svg, f"Residual vectors over the image plane after calibration (px; {what}), drawn {gain:.3g}× "
                   "longer than they are: a pattern (radial, a swirl, one side) means a lens or hand-eye effect the model "
                   "leaves out.", "fig-camera-quiver")
    cov = f.coverage()
    html += figure(coverage_plot(f), f"Coverage of the image: every detected corner (px, a colour per image) over "
                   f"the corner count per cell of a {GRID[0]}×{GRID[1]} grid; {int((cov > 0).sum())} of {cov.size} "
                   "cells hold corners (distortion is determined only where corners were seen).", "fig-camera-coverage")
    out = f.outliers()
    if out:
        html += f"<h3>Outlier corners ({len(out)})</h3>" + table(
            ["image", "corner", "u (px)", "v (px)", "du (px)", "dv (px)", "|r| (px)", "why"],
            [[escape(o["label"]), str(o["corner"]), f"{o['u_px']:.2f}", f"{o['v_px']:.2f}", f"{o['du_px']:+.4f}",
              f"{o['dv_px']:+.4f}", f"{o['norm_px']:.4f}", escape(o["why"])] for o in out[:50]], {1, 2, 3, 4, 5, 6})
        if len(out) > 50:
            html += f'<p class="note">… {len(out) - 50} more.</p>'
    else:
        html += f'<p class="note">No outlier corner (none rejected, none beyond {OUTLIER_SIGMAS:g} robust σ).</p>'
    return _section("camera", "Camera images", html)
