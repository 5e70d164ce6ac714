"""Held-out error that leaves out whole groups: sessions, placements, sockets.

A recording of several sessions (`pipeline.importers.merge`) or of a ball-in-socket tool at several
placements has groups whose rows share something the others do not (an instrument set-up, a socket
point).  Leaving out single rows keeps that shared part fitted, so the held-out error cannot see what
carries over to a new group.  Here each group in turn is left out: the model is fitted on the others,
then only what the left-out group has of its own — parameters no training row depends on (its socket
points, its own instrument frame) — is estimated from its rows with everything else held, and its
residuals are its held-out error.
"""

from __future__ import annotations

import numpy as np

from pipeline.identify.model import take


def row_groups(model, data) -> np.ndarray | None:
    """The group of each row, or None when the data have fewer than two: the session where several
    recordings were merged; else, for coincidences, the placement (``place/hole_k`` → ``place``) or,
    with a single placement, the socket."""
    n = len(data["joint_positions"])
    ses = data.get("session")
    if ses is not None and len(np.unique(ses)) > 1:
        return np.asarray(ses).astype(str)
    names = list(getattr(model, "groups_", ()) or getattr(getattr(model, "inner", None), "groups_", ()) or ())
    if not names or "group" not in data:
        return None
    lab = np.array([names[int(g)] for g in np.asarray(data["group"], int)], object)
    place = np.array([s.rsplit("/", 1)[0] if "/" in s else s for s in lab], object)
    g = place if len(np.unique(place)) > 1 else lab
    return g.astype(str) if len(np.unique(g)) > 1 else (None if n else None)


def own_parameters(model, x: np.ndarray, data, train: np.ndarray, test: np.ndarray) -> np.ndarray:
    """Indices of parameters the test rows depend on and no training row does."""
    J = np.asarray(model.jacobian(x, data), float)
    J = J.reshape(J.shape[0], -1, J.shape[-1])
    used_tr = np.any(J[train] != 0, axis=(0, 1))
    used_te = np.any(J[test] != 0, axis=(0, 1))
    return np.flatnonzero(used_te & ~used_tr)


def held_out(model, data, groups: np.ndarray, solve, x_start: np.ndarray) -> np.ndarray:
    """Residuals (n, residual_dim) of each group predicted by `solve(train_data, x_start) -> x` fitted on
    the other groups, the group's own parameters estimated from its rows (module docstring)."""
    from pipeline.identify.least_squares import FitOptions, fit

    n = len(data["joint_positions"])
    out = np.full((n, model.residual_dim), np.nan)
    names = model.parameter_names()
    linked = _linked(data, groups)
    for g in np.unique(groups):
        test = np.flatnonzero(groups == g)
        train = np.flatnonzero((groups != g) & ~linked(g))
        x = solve(take(data, train), x_start)
        own = own_parameters(model, x, data, train, test)
        d_test = take(data, test)
        if own.size:
            fixed = tuple(n_ for i, n_ in enumerate(names) if i not in set(own.tolist()))
            x = fit(model, d_test, FitOptions(fixed=fixed, x0=x, before=False)).x
        out[test] = np.asarray(model.residuals(x, d_test), float).reshape(len(test), -1)
    return out


def held_out_linear(model, data, groups: np.ndarray, x: np.ndarray, idx: np.ndarray, lam: np.ndarray,
                    centre: np.ndarray, J: np.ndarray | None = None, r: np.ndarray | None = None) -> np.ndarray:
    """`held_out` of the penalised fit min ‖r‖² + ‖lam·(x[idx] − centre[idx])‖² over x[idx], linearised at its
    all-groups solution `x`: each group's training fit is one Gauss-Newton step from `x` on the other groups'
    rows (its gradient there, (J_RᵀJ_R + lam²)⁻¹), then the group's own parameters are fitted to its rows by
    linear least squares — no solve per group.  `J` (n·residual_dim, P), `r` (n·residual_dim,): the Jacobian and
    residuals at `x` when the caller has them (or a linearisation of them).  Residuals (n, residual_dim)."""
    n, kd = len(data["joint_positions"]), model.residual_dim
    J = np.asarray(model.jacobian(x, data) if J is None else J, float).reshape(n * kd, -1)
    r = np.asarray(model.residuals(x, data) if r is None else r, float).ravel()
    Jx, pen = J[:, idx], lam**2 * (np.asarray(x, float)[idx] - np.asarray(centre, float)[idx])
    rows = lambda mask: (np.flatnonzero(mask)[:, None] * kd + np.arange(kd)).ravel()  # noqa: E731
    linked = _linked(data, groups)
    out = np.full((n, kd), np.nan)
    for g in np.unique(groups):
        te = groups == g
        T, R = rows(te), rows(~te & ~linked(g))
        A = Jx[R].T @ Jx[R] + np.diag(lam**2)
        step = np.linalg.pinv(A, rcond=1e-12, hermitian=True) @ (Jx[R].T @ r[R] + pen)
        rt = r[T] - Jx[T] @ step
        own = np.flatnonzero(np.any(J[T] != 0, axis=0) & ~np.any(J[R] != 0, axis=0))
        if own.size:
            rt = rt - J[T][:, own] @ np.linalg.lstsq(J[T][:, own], rt, rcond=None)[0]
        out[te] = rt.reshape(-1, kd)
    return out


def _linked(data, groups: np.ndarray):
    """g → mask of the rows outside g that still tie to g's own parameters: a known distance row
    (coincidence, ``kind`` 1) between a socket of g and one of another group."""
    n = len(groups)
    if "kind" not in data or "group_b" not in data:
        return lambda g: np.zeros(n, bool)
    kind, a, b = (np.asarray(data[c], int) for c in ("kind", "group", "group_b"))
    touch = kind == 0
    sock = {int(s): groups[i] for i, s in zip(np.flatnonzero(touch), a[touch])}
    ga = np.array([sock.get(int(s), "") for s in a], object)
    gb = np.array([sock.get(int(s), "") for s in b], object)
    return lambda g: (kind == 1) & ((ga == g) | (gb == g))


def per_group_rms(r: np.ndarray, groups: np.ndarray) -> dict[str, float]:
    """RMS of the residuals of each group (m)."""
    return {str(g): float(np.sqrt(np.nanmean(r[groups == g] ** 2))) for g in np.unique(groups)}
