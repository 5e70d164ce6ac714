"""Does a planned camera campaign beat random ones?  A simulated cell with known truth (the
planning cell plus errors), corner detections at the truth projected by OpenCV
(`cv2.projectPoints`, not robocal's projection) with Gaussian pixel noise, and the joint fit of
the planned images against the fits of random sets of as many candidate images.

Figures per set: each free parameter's stated σ (the fit's independent-corner σ, honest here:
the simulated corners' noise is independent) and its true error (RMS over noise draws), and two summaries over the
parameters all fits free — the geometric mean of σ relative to the median random set's σ, and the
RMS of the true errors in units of that median σ; plus the hand-eye translation error (mm) and
the focal length's error (px).
"""

from __future__ import annotations

import numpy as np

from pipeline.camera import projection as pj
from pipeline.identify.least_squares import FitOptions, fit


def true_cell(model, x: np.ndarray, rng: np.random.Generator, held: tuple[str, ...] = (), offset_rad: float = 2e-3,
              frame_m: float = 5e-3, frame_rad: float = 0.02,
              distortion: tuple = (-0.2, 0.05, 1e-3, -5e-4, 0.0)) -> np.ndarray:
    """The planning vector x plus errors (none on the parameters `held`: e.g. those the rank test
    does not free, whose error a free partner would absorb — j1's offset into the board's yaw —
    and make the truth ambiguous): joint offsets N(0, offset_rad), hand-eye and board frames N(0, frame_m / frame_rad), focal lengths
    ×N(1, 0.02), principal point N(0, 5 px), and the lens's distortion `distortion` (k1, k2, p1,
    p2, k3, … as the model's terms)."""
    t = np.array(x, float)
    names = model.parameter_names()
    for i, n in enumerate(names):
        if n in held:
            continue
        if n.endswith(".offset"):
            t[i] += rng.normal(0, offset_rad)
        elif n.startswith(("base.", "tool.")):
            t[i] += rng.normal(0, frame_m if n.split(".")[1] in ("x", "y", "z") else frame_rad)
    k = model.n_kin
    t[k:k + 2] *= rng.normal(1, 0.02, 2)
    t[k + 2:k + 4] += rng.normal(0, 5.0, 2)
    nd = model.n_dist
    t[k + 4:] = np.r_[distortion, np.zeros(8)][:nd]
    return t


def detections(model, truth: np.ndarray, q: np.ndarray, target, noise_px: float, rng: np.random.Generator) -> dict:
    """Camera table of images at q: every corner projected at the truth by `cv2.projectPoints`
    plus N(0, noise_px) per axis; images with a corner outside the image are dropped."""
    import cv2

    from pipeline.simulate.camera_images import board_in_camera

    k = model.split(truth)[1]
    T = board_in_camera(model, truth, q)
    w, h = model.image_size
    cols = {c: [] for c in ("joint_positions", "image", "corner", "point", "pixel")}
    for i in range(len(q)):
        rv = cv2.Rodrigues(T[i, :3, :3])[0]
        if model.lens == pj.FISHEYE:
            px = cv2.fisheye.projectPoints(target.points[:, None, :], rv, T[i, :3, 3], pj.camera_matrix(k), k[4:])[0]
        else:
            px = cv2.projectPoints(target.points, rv, T[i, :3, 3], pj.camera_matrix(k), k[4:])[0]
        px = px.reshape(-1, 2) + rng.normal(0, noise_px, (target.n_corners, 2))
        if np.any(px < 0) or np.any(px > np.array([w - 1, h - 1])):
            continue
        n = target.n_corners
        cols["joint_positions"].append(np.repeat(q[i][None], n, 0))
        cols["image"].append(np.full(n, i))
        cols["corner"].append(np.arange(n))
        cols["point"].append(target.points)
        cols["pixel"].append(px)
    t = {c: np.concatenate(v) for c, v in cols.items()}
    t["record"] = np.arange(len(t["image"]))
    return t


def fitted(model, table: dict, held: np.ndarray, x_held: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, σ, free) of the joint fit from OpenCV's start, the parameters `held` (mask) at `x_held`
    (OpenCV's start would put a held hand-eye yaw where it absorbs a joint offset's error)."""
    x0 = np.asarray(model.initial_guess(table), float)
    x0[held] = x_held[held]
    names = np.array(model.parameter_names())
    f = fit(model, table, FitOptions(x0=x0, fixed=tuple(names[held]), before=False))
    return f.x, f.std, f.free


def compare(model, truth: np.ndarray, q: np.ndarray, planned: np.ndarray, target, free: np.ndarray,
            n_random: int = 10, noise_px: float = 0.1, seed: int = 0, draws: int = 1) -> dict:
    """Planned images (indices into q) against `n_random` random sets of as many of q (module
    docstring); the parameters not `free` (the plan's mask) held at the truth's values.  Each set
    is fitted on `draws` noise draws: true errors are the RMS over them, σ the first draw's."""
    rng = np.random.default_rng(seed)
    m = len(planned)
    sets = [np.asarray(planned)] + [np.sort(rng.choice(len(q), m, replace=False)) for _ in range(n_random)]
    names = np.array(model.parameter_names())
    it, ifx = list(names).index("tool.x"), list(names).index("camera.fx")
    E, S, F, he, fx = [], [], [], [], []
    for s in sets:
        fits = [fitted(model, detections(model, truth, q[s], target, noise_px, rng), ~free, truth) for _ in range(draws)]
        e = np.array([x - truth for x, _, _ in fits])
        E.append(np.sqrt(np.mean(e ** 2, axis=0))), S.append(fits[0][1])
        F.append(np.logical_and.reduce([f for _, _, f in fits]))
        he.append(float(np.sqrt(np.mean(np.sum(e[:, it:it + 3] ** 2, axis=1)))) * 1e3)
        fx.append(float(np.sqrt(np.mean(e[:, ifx] ** 2))))
    common = np.logical_and.reduce(F)
    S, E = np.array(S)[:, common], np.array(E)[:, common]
    ref = np.median(S[1:], axis=0)
    sig = np.exp(np.mean(np.log(S / ref), axis=1))
    err = np.sqrt(np.mean((E / ref) ** 2, axis=1))
    return {"images": m, "random_sets": n_random, "noise_px": noise_px, "draws": draws,
            "parameters": names[common].tolist(), "planned_sigma": S[0].tolist(), "random_median_sigma": ref.tolist(),
            "planned_error": E[0].tolist(),
            "sigma_ratio_planned": float(sig[0]), "sigma_ratio_random": sig[1:].tolist(),
            "error_planned": float(err[0]), "error_random": err[1:].tolist(),
            "hand_eye_error_mm_planned": he[0], "hand_eye_error_mm_random": he[1:],
            "fx_error_px_planned": fx[0], "fx_error_px_random": fx[1:]}
