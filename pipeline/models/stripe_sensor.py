"""The laser-stripe scanner of seed 001 as an instrument part: a camera and a stripe projector
on the flange.  Fourteen parameters (`pipeline.models.camera`, eq. 14); a stripe pixel (U, V)
becomes a point of the laser plane in the flange frame, with its analytic derivatives.

A measurement type composes it with a robot (`pipeline.measurements.sensed_point`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.identify.model import Table
from pipeline.models import camera as cam


@dataclass(frozen=True)
class StripeSensor:
    prefix: str = "scanner"

    @property
    def n_params(self) -> int:
        return cam.N_SCANNER

    def parameter_names(self) -> list[str]:
        return [f"{self.prefix}.{n}" for n in cam.SCANNER_NAMES]

    def parameter_units(self) -> list[str]:
        return list(cam.SCANNER_UNITS)

    def flange_points(self, s: np.ndarray, data: Table, jac: bool = False, excess=None):
        """Stripe points in the flange frame (n, 3) m from ``data["pixel"]`` (n, 2) px, and with
        `jac` their derivatives (n, 3, 14) (else None).  `excess`: further lens terms
        (`camera.camera_points_jacobian`)."""
        px = np.asarray(data["pixel"], float)
        if not jac and excess is None:
            return cam.camera_to_flange(s, cam.camera_points(s, px)), None
        p_c, Jc = cam.camera_points_jacobian(s, px, excess)
        R_he = cam.hand_eye_rotation(s[cam.I_W], s[cam.I_PHI], s[cam.I_PSI])
        p_f = p_c @ R_he.T + s[cam.I_TX:cam.I_TZ + 1]
        J_f = np.empty((px.shape[0], 3, cam.N_SCANNER))
        J_f[:, :, :8] = np.einsum("ij,njk->nik", R_he, Jc)
        J_f[:, :, 8:] = cam.hand_eye_jacobian(s, p_c)
        return p_f, J_f
