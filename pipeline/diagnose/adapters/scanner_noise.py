"""The scanner's pose-error (repeatability) model: how a pose's error reaches its corners' residuals
(`pose_basis`), the physical mechanisms of the repeatability (`repeatability_basis`,
`repeatability_model`, `encoder_basis`) and their kinematic helpers (docs/guide/diagnose.md,
"Pose-clustered inference").  Split out of `scanner.py`, which re-exports every name."""

from __future__ import annotations

import numpy as np

from pipeline.models import camera as cam  # noqa: F401
from pipeline.models import serial_arm  # noqa: F401


def pose_basis(model, x: np.ndarray, table) -> np.ndarray:
    """How a pose's repeatability error reaches its corners (n, 3, 6): the flange (and so the
    camera) stands a small rigid motion (δt, δω) away from where the encoders say, which moves
    every reconstructed point P by δt + δω × (P − P̄) (P̄ the pose's mean point)."""
    P = model.residuals(x, table) + np.asarray(table["corner"], float)
    pose = np.asarray(table["pose"])
    _, inv = np.unique(pose, return_inverse=True)
    cnt = np.bincount(inv)
    Pm = np.stack([np.bincount(inv, P[:, a]) / cnt for a in range(3)], axis=1)[inv]
    d = P - Pm
    n = P.shape[0]
    Z = np.zeros((n, 3, 6))
    Z[:, :, :3] = np.eye(3)
    Z[:, 0, 4], Z[:, 0, 5] = d[:, 2], -d[:, 1]  # δω × d
    Z[:, 1, 3], Z[:, 1, 5] = -d[:, 2], d[:, 0]
    Z[:, 2, 3], Z[:, 2, 4] = d[:, 1], -d[:, 0]
    return Z


def repeatability_basis(model, x: np.ndarray, table) -> np.ndarray:
    """How a pose's repeatability error reaches its residuals (n, 3, 6), linearised: the flange
    stands (δt, δω) (m, rad; {B}) away from where the encoders say (R_f → (I + [δω]×) R_f, t_f →
    t_f + δt, the simulator's model).  The laser stripe then lands beside the grid line: the
    crossing of corner X slides in the target plane, along m (⟂ the stripe there), by −s/(n·m),
    s = δω·(n × (X − t_f)) − n·δt the corner's distance to the moved laser plane (n its normal
    in {B}); and the model, which places the camera where the encoders say, reconstructs that
    crossing moved back by δt + δω × (X − t_f).  Both are rigid motions of the pose's points,
    so span ⊂ `pose_basis`; what this adds is their covariance under a physical model
    (δt, δω isotropic, independent between poses)."""
    x = np.asarray(x, float)
    s = x[:cam.N_SCANNER]
    q = np.asarray(table["joint_positions"], float)
    X = np.asarray(table["corner"], float)
    R_f, t_f = model.flange(x, q)
    R_he = cam.hand_eye_rotation(s[cam.I_W], s[cam.I_PHI], s[cam.I_PSI])
    n_c, _ = cam.laser_plane(s)
    nrm = np.einsum("nij,jk,k->ni", R_f, R_he, n_c)  # laser plane normal in {B}
    _, _, Vt = np.linalg.svd(X - X.mean(axis=0), full_matrices=False)
    ez = Vt[2]  # the target plane's normal
    ell = np.cross(nrm, ez)
    ell /= np.linalg.norm(ell, axis=1, keepdims=True)
    m = np.cross(ez[None], ell)  # in the target plane, across the stripe
    nm = np.sum(nrm * m, axis=1)
    d = X - t_f
    n = X.shape[0]
    B = np.zeros((n, 3, 6))
    # slide: −s/(n·m)·m with s = δω·(n × d) − n·δt
    B[:, :, :3] += (m / nm[:, None])[:, :, None] * nrm[:, None, :]
    B[:, :, 3:] -= (m / nm[:, None])[:, :, None] * np.cross(nrm, d)[:, None, :]
    # moved back: −δt − δω × d = −δt + [d]× δω
    B[:, :, :3] -= np.eye(3)
    B[:, :, 3:] += _skew(d)
    return B


def repeatability_model(model, x: np.ndarray, table) -> tuple[np.ndarray, list[np.ndarray]]:
    """The pose error of a scanner campaign as four physical mechanisms (n, 3, 12 + 2·n_joints) with
    six variances (column groups).  Two are flange errors (δt, δω) with isotropic translation and
    rotation variances: the flange displaced after the stripe was put on the grid line
    (`repeatability_basis`: the crossing slides, the points move back) and the encoders misreading
    a flange that is where the stripe says (the points move back only: a pure rigid motion, which
    also reaches the off-plane rows that carry no measurement noise).  Two are joint-level, δq with
    one variance for all joints, shaped by the arm's Jacobian (anisotropic, pose-dependent): the
    encoders misreading the joints (`encoder_basis`: the pure rigid motion) and the arm standing δq
    off at the capture (the flange displaced by its twist J_f δq: the slide mechanism).  The data
    decide the six variances (`clustered.physical_components`)."""
    B = repeatability_basis(model, x, table)
    q = np.asarray(table["joint_positions"], float)
    X = np.asarray(table["corner"], float)
    R_f, t_f = model.flange(x, q)
    n, nj = X.shape[0], q.shape[1]
    Br = np.zeros((n, 3, 6))
    Br[:, :, :3] = -np.eye(3)
    Br[:, :, 3:] = -_skew(X - t_f)  # δω × d = −[d]× δω (a column's sign is immaterial to θ's covariance)
    F = serial_arm.frames(model._arm_vector(np.asarray(x, float)), q)
    Bq = joint_motion(F, X, nj)  # `encoder_basis`
    # the arm standing δq off at the capture: the flange displaced by its twist J_f δq (δt = ω_j × (t_f − o_j),
    # δω = ω_j per unit δq_j), the slide mechanism
    Bs = (np.einsum("nkc,ncj->nkj", B[:, :, :3], joint_motion(F, t_f, nj))
          + np.einsum("nkc,njc->nkj", B[:, :, 3:], F[:, :nj, :3, 2]))
    nq = 12 + nj
    groups = [np.arange(3 * i, 3 * i + 3) for i in range(4)] + [np.arange(12, nq), np.arange(nq, nq + nj)]
    return np.concatenate([B, Br, Bq, Bs], axis=2), groups


def encoder_basis(model, x: np.ndarray, table) -> np.ndarray:
    """How encoder misreadings reach a pose's residuals (n, 3, n_joints): the arm stands where the
    stripe was placed but the encoders read q + δq, so the model places the flange (camera and
    laser) at F(q + δq) and every reconstructed point moves rigidly by Σ_j δq_j ω_j × (X − o_j)
    (ω_j, o_j joint j's axis and origin in {B}).  Unlike the isotropic flange motion of
    `repeatability_model`'s second mechanism, this motion is anisotropic and pose-dependent (the
    arm's Jacobian): δq ~ N(0, θ I) per pose, one variance shared by all joints — a per-joint
    variance would let a structured error in one joint (a transmission bump) pass as noise."""
    q = np.asarray(table["joint_positions"], float)
    F = serial_arm.frames(model._arm_vector(np.asarray(x, float)), q)
    return joint_motion(F, np.asarray(table["corner"], float), q.shape[1])


def joint_motion(F: np.ndarray, X: np.ndarray, nj: int) -> np.ndarray:
    """Velocity (n, 3, nj) of points X (n, 3) in {B} per unit rotation of each of the first nj
    joints: ω_j × (X − o_j), ω_j and o_j joint j's axis and origin in {B} (`serial_arm.frames` F)."""
    return np.cross(F[:, :nj, :3, 2], X[:, None, :] - F[:, :nj, :3, 3]).transpose(0, 2, 1)


def _skew(d: np.ndarray) -> np.ndarray:
    """[d]× (n, 3, 3) of vectors d (n, 3): [d]× v = d × v."""
    S = np.zeros((d.shape[0], 3, 3))
    S[:, 0, 1], S[:, 0, 2] = -d[:, 2], d[:, 1]
    S[:, 1, 0], S[:, 1, 2] = d[:, 2], -d[:, 0]
    S[:, 2, 0], S[:, 2, 1] = -d[:, 1], d[:, 0]
    return S


def stripe_directions(table) -> np.ndarray:
    """Unit direction (n, 3, 1) in {B} of the grid line each pose's corners lie on: the printed
    corner's error along the stripe (the part across it only moves the crossing along the line)
    reaches the residual there, independently per corner."""
    C = np.asarray(table["corner"], float)
    pose = np.asarray(table["pose"]) if "pose" in table else np.zeros(len(C), int)
    out = np.zeros((len(C), 3, 1))
    for p in np.unique(pose):
        m = pose == p
        if m.sum() < 2:
            continue
        _, _, Vt = np.linalg.svd(C[m] - C[m].mean(axis=0), full_matrices=False)
        out[m, :, 0] = Vt[0]
    return out
