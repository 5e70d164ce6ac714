"""Rerun hook of the arc-welder (seed 000): the stepped jig and the touch residuals in 3-D.

``log_system(rec, model, table, x_before, x_after, artefacts=None)`` logs

- ``world/jig/blocks`` the jig's solid steps (boxes) and ``world/jig/faces`` each face's outline,
  labelled with its id;
- ``world/residuals/before`` (true scale) and ``world/residuals/after_x100`` (×100): for each
  contact, the vector from the model's tool tip to its face along the face axis;
- ``world/contacts`` the contact points on the faces (calibrated tip moved onto its face).
"""

from __future__ import annotations

import numpy as np
import rerun as rr

from pipeline.models.jig import Jig
from pipeline.recording.schemas import META_FIXTURE
from pipeline.visualize import scene

JIG_RGBA = (170, 175, 185, 110)
AFTER_SCALE = 100.0


def _jig(artefacts) -> Jig | None:
    meta = (getattr(artefacts, "recording", None) or {}).get("metadata", {})
    if META_FIXTURE in meta:
        return Jig.from_dict(meta[META_FIXTURE])
    return None


def log_jig(rec: rr.RecordingStream, jig: Jig) -> None:
    """Blocks and labelled face outlines (static)."""
    mins, sizes = scene.jig_blocks(jig)
    rec.log("world/jig/blocks", rr.Boxes3D(mins=mins, sizes=sizes, colors=[JIG_RGBA], fill_mode="solid"),
            static=True)
    outlines = [scene.face_outline(f) for f in jig.faces]
    rec.log("world/jig/faces", rr.LineStrips3D(outlines, colors=[(60, 60, 70)], radii=[0.0006],
                                               labels=[f.id for f in jig.faces], show_labels=True), static=True)


def log_system(rec: rr.RecordingStream, model, table: dict, x_before: np.ndarray, x_after: np.ndarray,
               artefacts=None) -> None:
    """Arc-welder scene: jig, contact points and residual vectors (see module docstring)."""
    from pipeline.models.jig import stepped_block

    log_jig(rec, _jig(artefacts) or stepped_block())
    axis = np.asarray(table["axis"], int)
    p0 = model.points(x_before, table)[0]
    p1 = model.points(x_after, table)[0]
    r0 = model.residuals(x_before, table)[:, 0]
    r1 = model.residuals(x_after, table)[:, 0]
    v0 = scene.touch_residual_vectors(r0, axis)
    v1 = scene.touch_residual_vectors(r1, axis)
    faces = [str(f) for f in table.get("face", [""] * len(axis))]
    rec.log("world/residuals/before", rr.Arrows3D(origins=p0, vectors=v0, colors=[(220, 80, 60)],
                                                  radii=[0.0008], labels=faces, show_labels=False), static=True)
    rec.log("world/residuals/after_x100", rr.Arrows3D(origins=p1, vectors=AFTER_SCALE * v1,
                                                      colors=[(40, 160, 90)], radii=[0.0008], labels=faces,
                                                      show_labels=False), static=True)
    rec.log("world/contacts", rr.Points3D(p1 + v1, colors=[(250, 200, 0)], radii=[0.0015], labels=faces,
                                          show_labels=False), static=True)
