"""Compensation for the Delta robot (seed 003): closed-form inverse kinematics of the calibrated
β' model (`pipeline.models.delta.inverse`), corrected targets by the nominal forward kinematics.

Targets are platform points P in the workcell (tracker) frame {T} (m) — the frame in which the
calibration's accuracy is defined (in {A} the origin is a gauge choice); the calibrated
registration maps them into the robot frame.  The corrected target is in the controller's own
{A} (nominal model: the β' nominal, whose extended terms are zero).  Position only (a Delta keeps
its platform's orientation).  The extended model (axis yaw/tilt, unequal rods) has no closed
form: its joints come from a vectorised damped Newton (`delta_newton.solve`) started from the
closed-form inverse of the calibration's simplified part.
"""

from __future__ import annotations

import numpy as np

from pipeline.compensate import delta_newton
from pipeline.compensate.serial import Compensated
from pipeline.models import delta as dm


def compensate(model, x_nominal: np.ndarray, x_calibrated: np.ndarray, p_t: np.ndarray,
               singular_threshold: float = 1e-3) -> Compensated:
    """Compensate platform-point targets p_t (N,3) m in {T}; `model` a `TrackerModel` (either variant)."""
    p_t = np.atleast_2d(np.asarray(p_t, float))
    n = p_t.shape[0]
    nb = model.n_beta
    b_n = model._simplified_beta(x_nominal[:nb])
    b_c = model._simplified_beta(x_calibrated[:nb])
    from pipeline.measurements.registration import registration_matrix

    def to_robot(x):  # workcell {T} → robot {A}: ᴬP = R·ᵀP + t (the model's registration)
        R, t = registration_matrix(model._split(x)[1])
        return p_t @ R.T + t

    q_nom, ok_nom = dm.inverse(model.delta, b_n, to_robot(x_nominal))
    q, ok = dm.inverse(model.delta, b_c, to_robot(x_calibrated))  # ok: every leg reaches, within travel
    if model.extended:  # from the β' closed form to the full model's solution; dP/dθ analytic
        q, _, Jq = delta_newton.solve(model.delta, x_calibrated[:nb], to_robot(x_calibrated), q)
        ok = np.all((q >= model.delta.lower) & (q <= model.delta.upper), axis=1)
    P, _ = model.points(x_calibrated, {"joint_positions": q})
    err = np.linalg.norm(P - p_t, axis=1)
    reach = err < 1e-9  # the closed form clips an unreachable leg, Newton stalls: forward kinematics misses
    pc, _ = dm.forward(model.delta, b_n, q)  # what a nominal controller must be told, in its {A}
    if not model.extended:  # conditioning: smallest singular value of dP/dθ (m per rad), central differences
        h = 1e-7
        Jq = np.stack([(dm.forward(model.delta, b_c, q + h * e)[0] - dm.forward(model.delta, b_c, q - h * e)[0])
                       / (2 * h) for e in np.eye(3)], axis=2)
    smin = np.linalg.svd(np.nan_to_num(Jq), compute_uv=False)[:, -1]
    status = np.full(n, "ok", dtype=object)
    status[~reach] = "unreachable"
    status[reach & ~ok] = "out_of_limits"
    status[(status == "ok") & (smin < singular_threshold)] = "singular"
    return Compensated(q_nominal=np.where(ok_nom[:, None], q_nom, np.nan), q=q, status=status, p_corrected=pc,
                       R_corrected=np.broadcast_to(np.eye(3), (n, 3, 3)).copy(), error_m=err, sigma_min_m=smin,
                       correction_m=np.linalg.norm(pc - to_robot(x_nominal), axis=1))
