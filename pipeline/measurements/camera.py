"""Camera measurements: a calibration board's corners seen in images, for any URDF robot.

One row per detected corner.  Data columns: ``joint_positions`` (n, n_joints) at the image,
``image`` (n,) int (rows of one image share it), ``corner`` (n,) the corner id, ``point``
(n,3) m the corner in the board frame, ``pixel`` (n,2) px where it was detected.  Residual:
projected − detected pixel, (n,2) **px**.

The chain's frames carry the hand-eye problem, so kinematics, hand-eye and board pose are one
least-squares problem (what OpenCV splits into calibrateCamera + calibrateHandEye):

* ``mount="tip"`` (eye-in-hand): the camera is the tool frame (``tool.*`` = flange → camera,
  the hand-eye transform); the board is fixed in the world and the chain's ``base.*`` is
  board → robot base.  A corner P_b in the camera frame: ``p_c = Rᵀ (P_b − p)``.
* ``mount="world"`` (eye-to-hand): the board is the tool frame (``tool.*`` = flange → board);
  the camera is the instrument frame (``base.*`` = camera → robot base).  ``p_c = R P_b + p``.

(R, p) is the chain's tool frame in its instrument frame.  The intrinsics ``camera.*`` follow
the chain's parameters (`pipeline.camera.projection`: pinhole with 4, 5 or 8 distortion terms,
or fisheye).  Groups for model selection: the intrinsics up to k1, k2, p1, p2 are fitted with
the registration; ``lens k3`` and ``lens k4-k6`` (rational) only where held-out error says the
data support them.  With ``kinematics_known`` (the robot's flange poses were measured, not its
joints) every kinematic parameter other than base and tool is held.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.camera import projection as pj
from pipeline.identify.model import Table
from pipeline.measurements.composed import Composed, skew
from pipeline.models import chain as ch


@dataclass(frozen=True)
class CameraModel(Composed):
    mount: str = "tip"  # tip: eye-in-hand; world: eye-to-hand
    lens: str = pj.PINHOLE
    n_dist: int = 5
    image_size: tuple[int, int] = (640, 480)  # width, height px: the nominal principal point and focal length
    kinematics_known: bool = False
    k_start: tuple | None = None  # intrinsics the camera states (a ROS CameraInfo's K, D): nominal and start
    residual_dim = 2
    residual_unit = "px"
    robust_scale = 0.5  # px: the scale of validate's robust outlier screen (a detector's gross error is pixels)

    # ----- extra parameters: the intrinsics ---------------------------------------------
    def extra_names(self) -> list[str]:
        return [f"camera.{n}" for n in pj.intrinsic_names(self.lens, self.n_dist)]

    def extra_units(self) -> list[str]:
        return pj.intrinsic_units(self.lens, self.n_dist)

    def extra_nominal(self) -> np.ndarray:
        if self.k_start is not None:
            return np.asarray(self.k_start, float)
        w, h = self.image_size
        return np.r_[float(w), float(w), (w - 1) / 2, (h - 1) / 2, np.zeros(self.n_dist)]

    def groups(self) -> dict[str, list[str]]:
        g = super().groups()
        lens = [n for n in self.extra_names() if n in ("camera.k3", "camera.k4", "camera.k5", "camera.k6")]
        if self.lens == pj.PINHOLE:
            g["registration"] = [n for n in g["registration"] if n not in lens]
            if "camera.k3" in lens:
                g["lens k3"] = ["camera.k3"]
            if self.n_dist == 8:
                g["lens k4-k6"] = ["camera.k4", "camera.k5", "camera.k6"]
        if self.kinematics_known:
            known = [n for k, v in list(g.items()) if k != "registration" and not k.startswith(("lens", "_"))
                     for n in v]
            g = {k: v for k, v in g.items() if k == "registration" or k.startswith(("lens", "_"))}
            g["_known kinematics"] = known
        return g

    # ----- the measurement -----------------------------------------------------------------
    def camera_points(self, x: np.ndarray, data: Table, jac: bool = True):
        """Corners in the camera frame (n,3) m and, with `jac`, the two factors of d/dx:
        d p_c = [p_c]× A − B (tip) or B − [R P_b]× A (world), A, B (n_images,3,P) indexed by
        the row's image (returned with that index); None without `jac`."""
        img = np.asarray(data["image"])
        _, first, inv = np.unique(img, return_index=True, return_inverse=True)
        q = np.asarray(data["joint_positions"], float)[first]
        P = np.asarray(data["point"], float)
        if jac:
            p, Jp, R, Jw = self.tool(x, q)
        else:
            R, p = ch.forward(self.kin.chain(), self.split(x)[0], q)
        if self.mount == "tip":  # p_c = Rᵀ(P − p): d p_c = [p_c]× Rᵀ δω − Rᵀ δp
            pc = np.einsum("nji,nj->ni", R[inv], P - p[inv])
            if not jac:
                return pc, None
            Rt = np.swapaxes(R, 1, 2)
            return pc, (pc, Rt @ Jw, -(Rt @ Jp), inv)
        w = np.einsum("nij,nj->ni", R[inv], P)  # p_c = R P + p: d p_c = δp − [R P]× δω
        pc = w + p[inv]
        if not jac:
            return pc, None
        return pc, (-w, Jw, Jp, inv)

    def predict(self, x: np.ndarray, data: Table, jac: bool = False):
        """Projected pixels (n,2) px and, with `jac`, d/dx (n,2,P)."""
        pc, parts = self.camera_points(x, data, jac)
        k = self.split(x)[1]
        if not jac:
            return pj.project(k, pc, self.lens), None
        uv, Jk, JP = pj.project(k, pc, self.lens, jac=True)
        a, A, B, inv = parts
        Jx = np.matmul(JP @ skew(a), A[inv]) + np.matmul(JP, B[inv])
        Jx[:, :, self.n_kin:] += Jk
        return uv, Jx

    def residuals(self, x: np.ndarray, data: Table) -> np.ndarray:
        return self.predict(x, data)[0] - np.asarray(data["pixel"], float)

    def jacobian(self, x: np.ndarray, data: Table) -> np.ndarray:
        return self.predict(x, data, jac=True)[1]

    def hand_eye_names(self) -> list[str]:
        """The hand-eye transform's parameters: flange → camera (``tool.*``, eye-in-hand) or camera →
        robot base (``base.*``, eye-to-hand); m and rad (URDF rpy)."""
        f = "tool" if self.mount == "tip" else "base"
        return [f"{f}.{a}" for a in ("x", "y", "z", "roll", "pitch", "yaw")]

    def holdout_groups(self, data: Table) -> np.ndarray:
        """Rows that must stay together in a held-out split: one image's corners."""
        return np.asarray(data["image"])

    def extra_metrics(self, x0: np.ndarray, x: np.ndarray, data: Table) -> dict:
        """Reprojection RMS (px) and the number of images."""
        r = self.residuals(x, data)
        return {"reprojection_rms_px": float(np.sqrt(np.mean(r**2))), "images": int(len(np.unique(data["image"])))}

    def resampled_covariance(self, x: np.ndarray, free: np.ndarray, data: Table) -> np.ndarray | None:
        """Covariance (F, F) of the free parameters by the delete-one-image jackknife
        (`pipeline.camera.uncertainty`): the corners of an image share its robot pose error, so the
        independent-corner σ̂²(JᵀJ)⁻¹ of the fit understates σ several fold (4–20× for a hand-eye on
        real images); this one does not.  None with fewer than 4 images."""
        from pipeline.camera.uncertainty import image_jackknife

        free = np.asarray(free, bool)
        if len(np.unique(data["image"])) < 4 or not free.any():
            return None
        _, est = image_jackknife(self, data, np.asarray(x, float), free)
        d = est[:, free] - est[:, free].mean(axis=0)
        G = len(est)
        return (G - 1) / G * d.T @ d

    def initial_guess(self, data: Table) -> np.ndarray:
        """OpenCV's two-step answer as the start: calibrateCamera on the detections (from `k_start`
        where the camera states its intrinsics), then calibrateHandEye (Park) against the nominal
        chain's flange poses (`pipeline.camera.start`)."""
        from pipeline.camera.start import opencv_start

        return opencv_start(self, data)
