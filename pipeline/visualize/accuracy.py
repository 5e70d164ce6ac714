"""run.rrd: the accuracy map — map points coloured by predicted 1σ, sized by the
95 % bound, labelled in mm; and the verdict as a text document."""

from __future__ import annotations

import numpy as np
import rerun as rr


def _viridis(t: np.ndarray) -> np.ndarray:
    """RGB (n,3) uint8 of t in [0, 1] on matplotlib's viridis."""
    from matplotlib import colormaps

    return (colormaps["viridis"](np.clip(t, 0, 1))[:, :3] * 255).astype(np.uint8)


def log_accuracy(rec: rr.RecordingStream, acc: dict) -> list[str]:
    m = acc.get("map", {})
    pts = np.asarray(m.get("points_m", []), float).reshape(-1, 3)
    sig = np.asarray(m.get("sigma_m", []), float)
    b95 = np.asarray(m.get("bound95_m", []), float)
    out = []
    if len(pts) and sig.size == len(pts):
        span = max(float(sig.max() - sig.min()), 1e-300)
        labels = [f"1σ {s * 1e3:.3g} mm, 95 % {b * 1e3:.3g} mm" for s, b in zip(sig, b95)]
        radii = 6e-3  # m; the colour carries the 1σ, the label both figures
        rec.log("world/accuracy_map", rr.Points3D(pts, colors=_viridis((sig - sig.min()) / span), radii=radii,
                                                  labels=labels, show_labels=False), static=True)
        out.append("world/accuracy_map")
    text = (f"## Accuracy: {acc.get('status', '?')}\n\n"
            + (f"**Reason:** {acc['reason']}\n\n**Advice:** {acc.get('advice', '')}\n\n" if acc.get("reason") else "")
            + f"- predicted 1σ over the map (RMS): {acc.get('map_rms_1sigma_m', 0) * 1e3:.3g} mm\n"
            + f"- worst 95 % bound: {acc.get('map_max_bound95_m', 0) * 1e3:.3g} mm\n"
            + f"- map: {m.get('description', '')}\n")
    rec.log("accuracy", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN), static=True)
    return out + ["accuracy"]
