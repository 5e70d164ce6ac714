"""Terms of the touched jig's faces: the face is not where, or not the plane, the drawing says.

- ``face_offset`` (per face, m): the machined face lies δ along its axis from the drawing value (a
  ``coordinate`` term; immaterial below the jig's machining tolerance);
- ``face_tilt`` (per face, m/m along each in-plane axis) and ``face_flatness`` (per face, 1/m, a
  bowl about the face's contacts' centre): the true tip meets the face displaced by D·θ along the
  face's axis of the jig frame {W} (``tip`` terms, in-plane coordinates of the tip in m).
"""

from __future__ import annotations

import numpy as np

from pipeline.diagnose.library.term import Effect, along_axis
from pipeline.models import serial_arm

PLAUSIBLE = {"face_offset": 1e-3, "face_tilt": 2e-3, "face_flatness": 0.1}  # m, m/m, 1/m
ADVICE = {
    "face_offset": "touch the face from poses far apart in joint space",
    "face_tilt": "spread the contacts over the whole face",
    "face_flatness": "spread the contacts over the whole face, centre and edges",
}


def _face(face_id):
    def basis(arm, x, t):
        return -(np.asarray(t["face"]).astype(str) == face_id).astype(float)[:, None]
    return basis


def _in_plane(arm, x, t, face: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(on-face mask, u, v) in-plane coordinates of the tip (m) about the face's contacts' centre."""
    on = np.asarray(t["face"]).astype(str) == face
    ax = np.asarray(t["axis"], int)
    p = serial_arm.tip_position(x, np.asarray(t["joint_positions"], float))
    a0 = int(ax[on][0]) if on.any() else 2
    a, b = [k for k in range(3) if k != a0]
    u = np.where(on, p[:, a] - (p[on, a].mean() if on.any() else 0), 0.0)
    v = np.where(on, p[:, b] - (p[on, b].mean() if on.any() else 0), 0.0)
    return on, u, v


def _tilt(face: str):
    def basis(arm, x, t):
        on, u, v = _in_plane(arm, x, t, face)
        return along_axis(t, np.stack([u, v], axis=1))
    return basis


def _flatness(face: str):
    def basis(arm, x, t):
        on, u, v = _in_plane(arm, x, t, face)
        w = u**2 + v**2
        w = np.where(on, w - (w[on].mean() if on.any() else 0), 0.0)
        return along_axis(t, w[:, None])
    return basis


def offset(face: str, jig_tolerance_m: float) -> Effect:
    return Effect("face_offset", face, (f"offset_{face}",), ("m",), PLAUSIBLE["face_offset"], "coordinate",
                  _face(face), 90, "face", ADVICE["face_offset"], tolerance=jig_tolerance_m)


def tilt(face: str) -> Effect:
    return Effect("face_tilt", face, (f"tilt_u_{face}", f"tilt_v_{face}"), ("m/m", "m/m"), PLAUSIBLE["face_tilt"], "tip",
                  _tilt(face), 92, "face", ADVICE["face_tilt"])


def flatness(face: str) -> Effect:
    return Effect("face_flatness", face, (f"bowl_{face}",), ("1/m",), PLAUSIBLE["face_flatness"], "tip",
                  _flatness(face), 94, "face", ADVICE["face_flatness"])
