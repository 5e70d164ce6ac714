"""Errors shared by the measurements of one robot configuration (functional core).

The corners a scanner sees from one pose, or readings repeated at one configuration, share the
robot's error at that pose (its repeatability, a flange not quite where it was sent): one rigid
error of the flange per configuration, on top of each measurement's own noise.  It moves a
measurement as a per-pose error of the frame that carries the sensor or tool would
(`POSE_FRAME`: the tool's or the scanner's hand-eye parameters), so the residual covariance is
Ω = σ_w² I + τ² B with B = blockdiag over configurations of J_S W J_Sᵀ (J_S those parameters'
Jacobian columns, W = 1 per metre and (1/LEVER)² per radian: τ is the flange's translation 1σ,
its rotation τ/LEVER).  A model without such parameters gets one error per configuration and
residual component (B = 1 between the same component of one configuration).  The fit's σ̂²(JᵀJ)⁻¹ assumes Ω = σ² I and so
understates the parameters' covariance: the least-squares estimate's covariance is the sandwich
J⁺ Ω J⁺ᵀ.

(σ_w², τ²) by the method of moments on the fit's residuals e = M ε (M = I − H, H = U Uᵀ):
E eᵀe = σ_w² tr M + τ² tr MB and E eᵀBe = σ_w² tr BM + τ² tr BMBM, solved for the pair (τ² ≥ 0).
Dense in the residuals (at most MAX_DENSE): larger campaigns are treated as independent.
"""

from __future__ import annotations

import numpy as np

MAX_DENSE = 3000  # residuals
#: Pose repeatability (3σ, m) of the robots of the bundled systems, from their datasheets
#: (SCORBOT-ER VII: ±0.2 mm); a robot model file's ``repeatability_3sigma_m`` overrides it.
DATASHEET_3SIGMA_M = {"scorbot-scanner": 2e-4}
LEVER = 0.3  # m: a flange rotation error of τ/LEVER rad moves a point at LEVER as much as τ does
#: Parameters whose per-configuration error stands for the flange's (name prefixes or full names).
POSE_FRAME = ("tool.", "hand_eye.", "scanner.tx", "scanner.ty", "scanner.tz", "scanner.w", "scanner.phi",
              "scanner.psi")


def pose_columns(names: list[str], units: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(indices of the POSE_FRAME parameters, their weights W: 1 for m, 1/LEVER² for rad)."""
    idx = [i for i, n in enumerate(names) if n.startswith(POSE_FRAME) and units[i] in ("m", "rad")]
    w = np.array([1.0 if units[i] == "m" else 1.0 / LEVER**2 for i in idx])
    return np.array(idx, int), w


def configuration_groups(data: dict) -> np.ndarray | None:
    """Group label (n,) of each measurement: measurements at the same joint configuration share
    one; None when no two do (or the table has no joint positions)."""
    q = data.get("joint_positions")
    if q is None:
        return None
    q = np.asarray(q, float)
    if q.ndim != 2 or not len(q):
        return None
    _, inv = np.unique(np.round(q, 9), axis=0, return_inverse=True)
    inv = np.asarray(inv).ravel()
    return inv if np.bincount(inv).max() > 1 else None


def shared_matrix(groups: np.ndarray, k: int, J_pose: np.ndarray | None = None,
                  weights: np.ndarray | None = None) -> np.ndarray:
    """B (n·k, n·k) of the module docstring: with J_pose (n·k, s) and weights (s,), J_S W J_Sᵀ
    between rows of one configuration; without, 1 between the same component of one configuration."""
    g = np.repeat(np.asarray(groups), k)
    same = g[:, None] == g[None, :]
    if J_pose is not None and J_pose.shape[1]:
        return np.where(same, (J_pose * weights) @ J_pose.T, 0.0)
    c = np.tile(np.arange(k), len(groups))
    return (same & (c[:, None] == c[None, :])).astype(float)


def moments(U: np.ndarray, B: np.ndarray) -> np.ndarray:
    """The 2×2 moment matrix [[tr M, tr MB], [tr BM, tr BMBM]]."""
    m = B.shape[0]
    M = np.eye(m) - U @ U.T
    MB = M @ B
    return np.array([[np.trace(M), np.trace(MB)], [np.trace(MB), np.sum(MB * MB.T)]])


def solve_moments(T: np.ndarray, ee: np.ndarray, eBe: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(σ_w², τ²) per set of quadratic forms (vectorised), τ² ≥ 0 (then σ_w² from the first moment)."""
    det = T[0, 0] * T[1, 1] - T[0, 1] * T[1, 0]
    w = (T[1, 1] * ee - T[0, 1] * eBe) / det
    t = (T[0, 0] * eBe - T[1, 0] * ee) / det
    neg = t < 0
    t = np.where(neg, 0.0, t)
    w = np.where(neg, ee / T[0, 0], w)
    w = np.clip(w, 0.0, None)
    return w, t


def repeatability(rec_meta: dict, system: str) -> float | None:
    """The robot's pose repeatability, 1σ m: the robot model file's ``repeatability_3sigma_m`` / 3,
    else the datasheet of the system's robot (DATASHEET_3SIGMA_M), else None (then estimated)."""
    v = (rec_meta or {}).get("repeatability_3sigma_m")
    if v is None:
        v = DATASHEET_3SIGMA_M.get(system)
    try:
        return None if v is None else float(v) / 3.0
    except (TypeError, ValueError):
        return None


def estimate(U: np.ndarray, residuals: np.ndarray, groups: np.ndarray, k: int, J_pose: np.ndarray | None = None,
             weights: np.ndarray | None = None, tau: float | None = None) -> dict | None:
    """σ_w and τ (m) from the in-sample residuals (n, k) — τ given (the robot's stated
    repeatability), then σ_w from the first moment — ; None when the campaign is too large for the
    dense estimate or the moments are degenerate.  Few configurations cannot separate τ from what
    the fit absorbs (five scanner poses estimate τ ≈ 0): state it where it is known."""
    e = np.asarray(residuals, float).reshape(-1)
    if e.size > MAX_DENSE:
        return None
    B = shared_matrix(groups, k, J_pose, weights)
    T = moments(U, B)
    if tau is not None:
        w = max(0.0, (float(e @ e) - tau**2 * T[0, 1]) / T[0, 0])
        return {"sigma_w_m": float(np.sqrt(w)), "tau_m": float(tau), "B": B, "T": T, "tau_source": "stated"}
    if abs(T[0, 0] * T[1, 1] - T[0, 1] * T[1, 0]) < 1e-12 * max(abs(T).max() ** 2, 1e-300):
        return None
    w, t = solve_moments(T, np.array([e @ e]), np.array([e @ B @ e]))
    return {"sigma_w_m": float(np.sqrt(w[0])), "tau_m": float(np.sqrt(t[0])), "B": B, "T": T,
            "tau_source": "estimated from the residuals"}


def sandwich(Jf: np.ndarray, sigma_w: float, tau: float, B: np.ndarray) -> np.ndarray:
    """Covariance (p, p) of the least-squares estimate under Ω = σ_w² I + τ² B."""
    from pipeline.accuracy.propagate import pinv

    Jp = pinv(Jf)
    return sigma_w**2 * Jp @ Jp.T + tau**2 * (Jp @ B) @ Jp.T
