"""Delta parallel robot of seed 003 (Jeong, Choi & Kim 2021): legs at φ = π/2, π, −π/2.

Frames (SI units, m and rad).  Base frame {A} = O-xyz at the centre of the three actuator
axes, z up; the moving platform hangs below (p_z < 0).  Leg i has the local frame
A_i-x_i y_i z_i = Rz(φ_i): x_i points from O towards actuator i, the actuator axis is y_i.
Actuator angle θ_1i is measured in the x_i-z_i plane from x_i towards +z_i (θ = 0: upper
arm horizontal, pointing outwards; positive raises the elbow).

Simplified error model β' (seed eq. 3), 9 per leg, in leg-local coordinates:
``da_x, da_y, da_z`` (base revolute joint position error), ``dtheta1`` (actuator offset),
``dl1`` (upper arm), ``dl2`` (parallelogram rods, both equal), ``db_x, db_y, db_z`` (platform
joint position error).  With it the vector loop is (seed eqs. 4–5)

    (l2+Δl2_i) u_i = Rz(φ_i)ᵀ p + d_i,
    d_i = ( −(l1+Δl1)c(θ+Δθ) − (a+Δa_x) + (b+Δb_x),  −Δa_y+Δb_y,  −(l1+Δl1)s(θ+Δθ) − Δa_z+Δb_z ),

and p follows in closed form from a quadratic in p_z (seed eqs. 6–11).  The physical root is
the lower one (platform below the elbows).

Full ("extended") model, used by the simulator's ``full`` truth and by the extended
identification: per leg also ``dgamma`` (actuator axis yaw about z_i), ``dalpha`` (axis tilt
about x_i) and ``dl2_diff`` (rod-length difference of the parallelogram; rods are
l2+Δl2 ± dl2_diff/2, half-width w).  The platform may then tilt; its pose (p, R_P) solves the
six rod constraints by Newton from the simplified solution.  The tracker's reflector sits at
``−h_M`` along the platform's w axis (seed eq. 13).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import lru_cache

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.models.transforms import rot

LEG_KEYS = ("da_x", "da_y", "da_z", "dtheta1", "dl1", "dl2", "db_x", "db_y", "db_z")
EXT_KEYS = ("dgamma", "dalpha", "dl2_diff")
_LEG_ANGLES = {"dtheta1", "dgamma", "dalpha"}
PHI = (np.pi / 2, np.pi, -np.pi / 2)


@dataclass(frozen=True)
class Delta:
    """Nominal description of a 3-DOF Delta robot (m, rad).  See docs/reference/systems/delta.md for the source
    of the default dimensions."""

    name: str = "delta 90° (robocal nominal)"
    a: float = 0.200  # actuator axis distance from O (fixed platform radius), m
    b: float = 0.050  # platform joint distance from P (moving platform radius), m
    l1: float = 0.350  # upper arm (actuated link), m
    l2: float = 0.800  # parallelogram rods, m
    w: float = 0.050  # half-width of the parallelogram (full model only), m
    phi: tuple[float, float, float] = PHI
    lower: float = float(np.radians(-70.0))  # actuator travel, rad
    upper: float = float(np.radians(80.0))

    @property
    def n_legs(self) -> int:
        return len(self.phi)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["phi"] = list(self.phi)
        return {"kind": "delta", **d, "units": {"length": "m", "angle": "rad"}}

    @classmethod
    def from_dict(cls, d: dict) -> "Delta":
        if d.get("kind") != "delta":
            raise ValueError(f"robot model kind is {d.get('kind')!r}, expected 'delta'")
        keys = ("name", "a", "b", "l1", "l2", "w", "lower", "upper")
        kw = {k: (str(d[k]) if k == "name" else float(d[k])) for k in keys if k in d}
        if "phi" in d:
            kw["phi"] = tuple(float(v) for v in d["phi"])
            if len(kw["phi"]) != 3:
                raise ValueError("a Delta robot has 3 legs (phi must have 3 angles)")
        return cls(**kw)


def beta_names(n_legs: int = 3, extended: bool = False) -> list[str]:
    """Names of the error parameters, leg by leg: β' (9 per leg) then, if extended, 3 more."""
    keys = LEG_KEYS + (EXT_KEYS if extended else ())
    return [f"leg{i + 1}.{k}" for i in range(n_legs) for k in keys]


def beta_units(n_legs: int = 3, extended: bool = False) -> list[str]:
    keys = LEG_KEYS + (EXT_KEYS if extended else ())
    return ["rad" if k in _LEG_ANGLES else "m" for _ in range(n_legs) for k in keys]


def split(beta: np.ndarray, extended: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(3, 9) β' and (3, 3) extended errors (zeros when not extended) of a flat vector."""
    beta = np.asarray(beta, float)
    k = len(LEG_KEYS) + (len(EXT_KEYS) if extended else 0)
    B = beta.reshape(3, k)
    return B[:, :9], (B[:, 9:] if extended else np.zeros((3, 3)))


@lru_cache(maxsize=16)
def _rz_cached(phi: tuple[float, ...]) -> np.ndarray:
    R = rot("z", np.asarray(phi))
    R.setflags(write=False)
    return R


def _rz(delta: Delta) -> np.ndarray:
    """(3, 3, 3) leg rotations Rz(φ_i): leg-local -> base."""
    return _rz_cached(tuple(delta.phi))


# ----- simplified model (seed eqs. 4-11) -------------------------------------------------
def leg_offsets(delta: Delta, beta: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """d_i of eq. 5, (N, 3 legs, 3) m in leg-local coordinates, and rod lengths L_i (3,) m."""
    B, _ = split(beta)
    theta = np.atleast_2d(np.asarray(theta, float))
    psi = theta + B[:, 3]
    l1 = delta.l1 + B[:, 4]
    d = np.empty(theta.shape + (3,))
    d[..., 0] = -l1 * np.cos(psi) - (delta.a + B[:, 0]) + (delta.b + B[:, 6])
    d[..., 1] = -B[:, 1] + B[:, 7]
    d[..., 2] = -l1 * np.sin(psi) - B[:, 2] + B[:, 8]
    return d, delta.l2 + B[:, 5]


def forward(delta: Delta, beta: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Analytic forward kinematics with β' (seed eqs. 8–11): platform point P in {A}, (N, 3) m,
    for actuator angles theta (N, 3) rad; and ok (N,) — False where there is no real root
    (the legs cannot close) or the elimination is degenerate (q2 ≈ 0).  Rows that are not ok
    hold the nearest real solution (discriminant clipped at 0) or NaN."""
    d, L = leg_offsets(delta, np.asarray(beta, float), theta)
    phi = np.asarray(delta.phi)
    c, s = np.cos(phi), np.sin(phi)
    dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]
    ex = 2 * (c * dx - s * dy)  # (N,3): coefficient of p_x in eq. 7
    ey = 2 * (s * dx + c * dy)
    ez = 2 * dz
    e0 = dx**2 + dy**2 + dz**2 - L**2
    # eq. 8 (j = 2, 3): leg 1 minus leg j
    e1 = ex[:, :1] - ex[:, 1:]
    e2 = ey[:, :1] - ey[:, 1:]
    e3 = ez[:, :1] - ez[:, 1:]
    e4 = e0[:, :1] - e0[:, 1:]
    (e12, e13), (e22, e23), (e32, e33), (e42, e43) = e1.T, e2.T, e3.T, e4.T
    q0 = e22 * e33 - e23 * e32  # eq. 9
    q1 = e13 * e32 - e12 * e33
    q2 = e12 * e23 - e22 * e13
    q3 = e22 * e43 - e23 * e42
    q4 = e13 * e42 - e12 * e43
    q5, q6, q7, q8 = ex[:, 0], ey[:, 0], ez[:, 0], e0[:, 0]  # eq. 10
    scale = delta.l1 * delta.a
    good_q2 = np.abs(q2) > 1e-9 * scale * scale
    q2s = np.where(good_q2, q2, 1.0)
    k0 = 1 + (q0**2 + q1**2) / q2s**2  # eq. 11
    k1 = 2 * (q0 * q3 + q1 * q4) / q2s**2 + (q0 * q5 + q1 * q6) / q2s + q7
    k2 = (q3**2 + q4**2) / q2s**2 + (q3 * q5 + q4 * q6) / q2s + q8
    disc = k1**2 - 4 * k0 * k2
    ok = good_q2 & (disc >= 0) & np.all(np.isfinite(d), axis=(1, 2))
    pz = (-k1 - np.sqrt(np.clip(disc, 0, None))) / (2 * k0)  # lower root: platform below
    p = np.stack([(q0 * pz + q3) / q2s, (q1 * pz + q4) / q2s, pz], axis=-1)
    p[~good_q2] = np.nan
    return p, ok


def rods(delta: Delta, beta: np.ndarray, theta: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Rod vectors (l2+Δl2_i)·u_i in {A}, (N, 3 legs, 3) m: elbow -> platform joint."""
    d, _ = leg_offsets(delta, beta, theta)
    return np.asarray(p)[:, None, :] + np.einsum("lij,nlj->nli", _rz(delta), d)


def forward_jacobian(delta: Delta, beta: np.ndarray, theta: np.ndarray, p: np.ndarray) -> np.ndarray:
    """dp/dβ' (N, 3, 27) by the implicit-function theorem on g_i = |Rz(φ_i)ᵀp + d_i|² − L_i².

    dg_i/dp = 2 w_iᵀ (w_i the rod vector in {A}); dg_i/dd_i = 2 v_iᵀ (v_i = Rz(φ_i)ᵀ w_i);
    dg_i/dL_i = −2 L_i;  dp/dβ = −(dg/dp)⁻¹ dg/dβ."""
    beta = np.asarray(beta, float)
    B, _ = split(beta)
    theta = np.atleast_2d(np.asarray(theta, float))
    n = theta.shape[0]
    d, L = leg_offsets(delta, beta, theta)
    v = np.einsum("lji,nlj->nli", _rz(delta), np.asarray(p)[:, None, :]) + d  # local rod vectors
    w = np.einsum("lij,nlj->nli", _rz(delta), v)
    psi = theta + B[:, 3]
    l1 = delta.l1 + B[:, 4]
    # dd/dβ per leg: (N, leg, 3 comps, 9 params); dL/dβ: only dl2
    D = np.zeros((n, 3, 3, 9))
    D[:, :, 0, 0] = D[:, :, 1, 1] = D[:, :, 2, 2] = -1.0
    D[:, :, 0, 6] = D[:, :, 1, 7] = D[:, :, 2, 8] = 1.0
    D[:, :, 0, 3] = l1 * np.sin(psi)
    D[:, :, 2, 3] = -l1 * np.cos(psi)
    D[:, :, 0, 4] = -np.cos(psi)
    D[:, :, 2, 4] = -np.sin(psi)
    G = 2 * np.einsum("nlc,nlck->nlk", v, D)  # (N, leg, 9)
    G[:, :, 5] -= 2 * L
    Gp = 2 * w  # (N, leg, 3)
    Ginv = np.linalg.inv(Gp)  # (N, 3 xyz, 3 legs)
    # block structure: leg l's parameters only enter g_l
    J = -Ginv[:, :, :, None] * G[:, None, :, :]  # (N, 3, leg, 9)
    return J.reshape(n, 3, 27)


def inverse(delta: Delta, beta: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse kinematics with β' (for commanding): actuator angles (N, 3) rad placing P at p
    (N, 3) m, elbows out; ok (N,) False where a leg cannot reach or leaves its travel."""
    B, _ = split(np.asarray(beta, float))
    p = np.atleast_2d(np.asarray(p, float))
    local = np.einsum("lji,nj->nli", _rz(delta), p)  # Rz(φ)ᵀ p, (N, leg, 3)
    # platform joint minus base joint, leg-local (the part of d_i that does not depend on θ)
    v = local + np.stack([delta.b + B[:, 6] - delta.a - B[:, 0], B[:, 7] - B[:, 1], B[:, 8] - B[:, 2]], axis=-1)
    l1 = delta.l1 + B[:, 4]
    L = delta.l2 + B[:, 5]
    # |v − l1 u(ψ)|² = L²  ->  v_x cψ + v_z sψ = K
    K = (np.sum(v**2, axis=-1) + l1**2 - L**2) / (2 * l1)
    R = np.hypot(v[..., 0], v[..., 2])
    ratio = K / R
    ok_leg = np.abs(ratio) <= 1
    psi = np.arctan2(v[..., 2], v[..., 0]) + np.arccos(np.clip(ratio, -1, 1))
    theta = np.angle(np.exp(1j * (psi - B[:, 3])))
    ok_leg &= (theta >= delta.lower) & (theta <= delta.upper)
    return theta, np.all(ok_leg, axis=1)


# ----- full model (simulator truth, extended identification) -----------------------------
def _leg_points(delta: Delta, beta: np.ndarray, theta: np.ndarray, extended: bool):
    """Elbow ball joints E (N, 3, 2, 3) and platform ball joints C (3, 2, 3) relative to P in
    the platform frame, rod lengths L (3, 2), plus pieces for derivatives."""
    B, X = split(beta, extended)
    theta = np.atleast_2d(np.asarray(theta, float))
    Rz = _rz(delta)
    Q = rot("z", X[:, 0]) @ rot("x", X[:, 1])  # (3,3,3) leg-local axis rotation
    psi = theta + B[:, 3]
    l1 = delta.l1 + B[:, 4]
    u = np.stack([np.cos(psi), np.zeros_like(psi), np.sin(psi)], axis=-1)  # (N, leg, 3)
    sgn = np.array([1.0, -1.0])
    ey = np.array([0.0, 1.0, 0.0])
    A = np.stack([delta.a + B[:, 0], B[:, 1], B[:, 2]], axis=-1)  # (leg, 3)
    arm = l1[None, :, None] * u  # (N, leg, 3)
    local_E = A[None, :, None, :] + np.einsum("lij,nlj->nli", Q, arm)[:, :, None, :] \
        + sgn[None, None, :, None] * delta.w * (Q @ ey)[None, :, None, :]
    E = np.einsum("lij,nlsj->nlsi", Rz, local_E)
    Bv = np.stack([delta.b + B[:, 6], B[:, 7], B[:, 8]], axis=-1)
    local_C = Bv[:, None, :] + sgn[None, :, None] * delta.w * ey
    C = np.einsum("lij,lsj->lsi", Rz, local_C)
    L = delta.l2 + B[:, 5][:, None] + sgn[None, :] * X[:, 2][:, None] / 2
    return E, C, L, (B, X, Q, u, psi, l1, sgn)


def full_forward(delta: Delta, beta: np.ndarray, theta: np.ndarray, extended: bool = True,
                 iters: int = 20) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Forward kinematics of the full model: platform point p (N, 3) m and orientation R_P
    (N, 3, 3) in {A}, ok (N,).  Newton on the six rod constraints from the simplified solution
    with R_P = I (the assembly branch of the real robot)."""
    theta = np.atleast_2d(np.asarray(theta, float))
    B, _ = split(beta, extended)
    p, ok = forward(delta, B.ravel(), theta)
    p = np.where(ok[:, None], p, np.array([0.0, 0.0, -delta.l2]))
    R = np.broadcast_to(np.eye(3), (theta.shape[0], 3, 3)).copy()
    E, C, L, _ = _leg_points(delta, beta, theta, extended)
    Cf = C.reshape(6, 3)
    Ef = E.reshape(-1, 6, 3)
    Lf = L.reshape(6)
    for _ in range(iters):
        RC = np.einsum("nij,kj->nki", R, Cf)
        w = p[:, None, :] + RC - Ef
        g = np.sum(w**2, axis=-1) - Lf**2
        G = np.concatenate([2 * w, 2 * np.cross(RC, w)], axis=-1)  # (N, 6, 6)
        step = np.linalg.solve(G, -g[..., None])[..., 0]
        p = p + step[:, :3]
        R = Rotation.from_rotvec(step[:, 3:]).as_matrix() @ R
        if np.max(np.abs(step), initial=0.0) < 1e-13:  # m and rad: converged to round-off
            break
    RC = np.einsum("nij,kj->nki", R, Cf)
    g = np.sum((p[:, None, :] + RC - Ef) ** 2, axis=-1) - Lf**2
    ok = ok & np.all(np.abs(g) < 1e-12, axis=1) & (np.abs(Rotation.from_matrix(R).magnitude()) < 0.5)
    return p, R, ok


def full_jacobian(delta: Delta, beta: np.ndarray, theta: np.ndarray, p: np.ndarray, R: np.ndarray,
                  offset: np.ndarray, extended: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Implicit-function derivatives of the full model at a solution (p, R_P).

    Returns d(p + R_P·offset)/dβ (N, 3, P) and d(R_P·offset)/d(offset_z) (N, 3), where offset is
    a point fixed to the platform (e.g. the reflector, (0, 0, −h_M)).  P = 36 (extended) or 27."""
    theta = np.atleast_2d(np.asarray(theta, float))
    n = theta.shape[0]
    E, C, L, (B, X, Q, u, psi, l1, sgn) = _leg_points(delta, beta, theta, extended)
    Rz = _rz(delta)
    RC = np.einsum("nij,lsj->nlsi", R, C)  # (N, leg, 2, 3)
    w = p[:, None, None, :] + RC - E  # (N, leg, 2, 3)
    Gz = np.concatenate([2 * w, 2 * np.cross(RC, w)], axis=-1).reshape(n, 6, 6)
    k = 12 if extended else 9
    # dE/dparam, dC/dparam (base frame), dL/dparam: per leg, (N, leg, 2, 3, k)
    dE = np.zeros((n, 3, 2, 3, k))
    dC = np.zeros((3, 2, 3, k))
    dL = np.zeros((3, 2, k))
    for c in range(3):
        dE[..., c] = Rz[None, :, None, :, c]  # da_x, da_y, da_z
        dC[..., 6 + c] = Rz[:, None, :, c]  # db_x, db_y, db_z
    du = np.stack([-np.sin(psi), np.zeros_like(psi), np.cos(psi)], axis=-1)
    dE[..., 3] = np.einsum("lij,ljk,nlk->nli", Rz, Q, l1[None, :, None] * du)[:, :, None, :]
    dE[..., 4] = np.einsum("lij,ljk,nlk->nli", Rz, Q, u)[:, :, None, :]
    dL[:, :, 5] = 1.0
    if extended:
        g_, a_ = X[:, 0], X[:, 1]
        dRz = np.stack([np.stack([-np.sin(g_), -np.cos(g_), 0 * g_], -1),
                        np.stack([np.cos(g_), -np.sin(g_), 0 * g_], -1), np.zeros((3, 3))], -2)
        dRx = np.stack([np.zeros((3, 3)), np.stack([0 * a_, -np.sin(a_), -np.cos(a_)], -1),
                        np.stack([0 * a_, np.cos(a_), -np.sin(a_)], -1)], -2)
        dQg = dRz @ rot("x", a_)
        dQa = rot("z", g_) @ dRx
        ey = np.array([0.0, 1.0, 0.0])
        lever = (l1[None, :, None] * u)[:, :, None, :] + sgn[None, None, :, None] * delta.w * ey  # (N,leg,2,3)
        dE[..., 9] = np.einsum("lij,ljk,nlsk->nlsi", Rz, dQg, lever)
        dE[..., 10] = np.einsum("lij,ljk,nlsk->nlsi", Rz, dQa, lever)
        dL[:, :, 11] = sgn[None, :] / 2
    RdC = np.einsum("nij,lsjk->nlsik", R, dC)
    Gb = 2 * np.einsum("nlsi,nlsik->nlsk", w, RdC - dE) - 2 * (L * 1.0)[None, :, :, None] * dL[None]
    # leg l's parameters only act on its own two rods: block-expand to (N, 6, 3k)
    Gfull = np.zeros((n, 3, 2, 3, k))
    for leg in range(3):
        Gfull[:, leg, :, leg, :] = Gb[:, leg]
    Gfull = Gfull.reshape(n, 6, 3 * k)
    dz = -np.linalg.solve(Gz, Gfull)  # (N, 6, 3k): dp (3) and dρ (3)
    Ro = np.einsum("nij,j->ni", R, offset)
    # d(R o)/dρ = −[R o]×
    cross = np.zeros((n, 3, 3))
    cross[:, 0, 1], cross[:, 0, 2] = -Ro[:, 2], Ro[:, 1]
    cross[:, 1, 0], cross[:, 1, 2] = Ro[:, 2], -Ro[:, 0]
    cross[:, 2, 0], cross[:, 2, 1] = -Ro[:, 1], Ro[:, 0]
    J = dz[:, :3] - np.einsum("nij,njk->nik", cross, dz[:, 3:])
    return J, R[:, :, 2]


def full_theta_jacobian(delta: Delta, beta: np.ndarray, theta: np.ndarray, p: np.ndarray,
                        R: np.ndarray, extended: bool = True) -> np.ndarray:
    """dp/dθ (N, 3, 3) m/rad of the full model at a solution (p, R_P): the implicit-function
    derivative for the actuator angles alone (θ_i moves both elbow balls of leg i by
    Rz·Q·l1·du/dψ), i.e. the Δθ_i columns of `full_jacobian` at a fraction of its cost."""
    theta = np.atleast_2d(np.asarray(theta, float))
    n = theta.shape[0]
    E, C, _, (_, _, Q, _, psi, l1, _) = _leg_points(delta, beta, theta, extended)
    RC = np.einsum("nij,lsj->nlsi", R, C)
    w = p[:, None, None, :] + RC - E  # (N, leg, 2, 3)
    Gz = np.concatenate([2 * w, 2 * np.cross(RC, w)], axis=-1).reshape(n, 6, 6)
    du = np.stack([-np.sin(psi), np.zeros_like(psi), np.cos(psi)], axis=-1)
    dE = np.einsum("lij,ljk,nlk->nli", _rz(delta), Q, l1[None, :, None] * du)  # (N, leg, 3)
    G = np.zeros((n, 3, 2, 3))  # rows (leg, rod), column: the leg's own θ
    G[:, np.arange(3), :, np.arange(3)] = -2 * np.einsum("nlsi,nli->lns", w, dE)
    return -np.linalg.solve(Gz, G.reshape(n, 6, 3))[:, :3]


def geometry(delta: Delta, beta: np.ndarray, theta: np.ndarray, p: np.ndarray) -> dict[str, np.ndarray]:
    """Points for drawing (simplified model): base joints, elbows, platform joints, (N, 3, 3) m."""
    B, _ = split(np.asarray(beta, float))
    theta = np.atleast_2d(np.asarray(theta, float))
    Rz = _rz(delta)
    A = np.stack([delta.a + B[:, 0], B[:, 1], B[:, 2]], axis=-1)
    psi = theta + B[:, 3]
    l1 = delta.l1 + B[:, 4]
    elbow_local = A[None] + l1[None, :, None] * np.stack([np.cos(psi), 0 * psi, np.sin(psi)], -1)
    Bv = np.stack([delta.b + B[:, 6], B[:, 7], B[:, 8]], axis=-1)
    base = np.broadcast_to(np.einsum("lij,lj->li", Rz, A), elbow_local.shape)
    return {"base": base, "elbow": np.einsum("lij,nlj->nli", Rz, elbow_local),
            "platform": np.asarray(p)[:, None, :] + np.einsum("lij,lj->li", Rz, Bv)[None]}
