"""A kinematic chain as a product of elementary steps, evaluated over a whole campaign at once.

Every serial model in robocal — seed 000's D-H + Hayati arm, a URDF robot with its joint-origin
error model — is one ``Chain``: a sequence of steps, each

* ``const``: a fixed 4×4 transform (a URDF fixed joint, a nominal origin rotation),
* ``rot``:   a rotation about a unit axis given in the frame before the step, by
  ``x[param] + q[:, joint]`` (either part may be absent),
* ``trans``: a translation along such an axis by the same kind of value.

The description (`Chain`, immutable) is kept apart from what is computed from it
(`forward`, `jacobian`, `joint_jacobian`, `frames`: pure functions of (chain, x, q)).  The
frame in which the chain starts is the caller's (a jig, a tracker, the world), in m and rad.

Derivatives use the screw form: a rotation step about world axis u through point o moves a
point p by u × (p − o) and turns the frame by u; a translation step moves p by u.  Steps
without a joint are folded, per parameter vector, into one 4×4 per run (memoised), so a batch
costs a few small array operations per joint.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CONST, ROT, TRANS = 0, 1, 2
_UNIT = np.eye(3)


@dataclass(frozen=True, eq=False)
class Chain:
    """Steps of a kinematic chain (arrays of length S) over `n_params` parameters and
    `n_joints` joint variables.  ``axis`` (S,3) unit vectors, ``param``/``joint`` (S,) int
    (−1: none), ``const`` (S,4,4) used by ``const`` steps only."""

    kind: np.ndarray
    axis: np.ndarray
    param: np.ndarray
    joint: np.ndarray
    const: np.ndarray
    n_params: int
    n_joints: int

    @staticmethod
    def build(steps: list[tuple], n_params: int, n_joints: int) -> "Chain":
        """From tuples ``(kind, axis, param, joint)`` or ``(CONST, T4x4)``."""
        S = len(steps)
        kind = np.zeros(S, int)
        axis = np.zeros((S, 3))
        param = np.full(S, -1)
        joint = np.full(S, -1)
        const = np.broadcast_to(np.eye(4), (S, 4, 4)).copy()
        for s, st in enumerate(steps):
            kind[s] = st[0]
            if st[0] == CONST:
                const[s] = np.asarray(st[1], float)
                continue
            a = np.asarray(st[1], float)
            axis[s] = a / np.linalg.norm(a)
            param[s], joint[s] = st[2], st[3]
        for arr in (kind, axis, param, joint, const):
            arr.setflags(write=False)
        return Chain(kind, axis, param, joint, const, n_params, n_joints)

    @property
    def n_steps(self) -> int:
        return len(self.kind)

    def runs(self) -> list[tuple[int, int]]:
        """Half-open index ranges of the chain: each joint step alone, the steps between folded."""
        out, s, S = [], 0, self.n_steps
        while s < S:
            if self.joint[s] >= 0:
                out.append((s, s + 1))
                s += 1
                continue
            e = s
            while e < S and self.joint[e] < 0:
                e += 1
            out.append((s, e))
            s = e
        return out


def _rodrigues(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotations (N,3,3) about one unit axis by N angles."""
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def _value(chain: Chain, x: np.ndarray, s: int) -> float:
    return float(x[chain.param[s]]) if chain.param[s] >= 0 else 0.0


def _step_matrices(chain: Chain, x: np.ndarray, s: int, e: int) -> np.ndarray:
    """The 4×4 transforms (e−s,4,4) of steps s..e−1 at parameters x, all at once: a constant step's
    own matrix, a rotation by Rodrigues' formula about its unit axis, a translation along its axis."""
    kind, axis, p = chain.kind[s:e], chain.axis[s:e], chain.param[s:e]
    v, has = np.zeros(e - s), p >= 0
    v[has] = x[p[has]]
    M = chain.const[s:e].copy()  # the identity where the step is not a constant one
    rot = np.flatnonzero(kind == ROT)
    if rot.size:
        a = axis[rot]
        K = np.zeros((rot.size, 3, 3))
        K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -a[:, 2], a[:, 1], -a[:, 0]
        K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = a[:, 2], -a[:, 1], a[:, 0]
        sn, c = np.sin(v[rot])[:, None, None], np.cos(v[rot])[:, None, None]
        M[rot, :3, :3] = np.eye(3) + sn * K + (1 - c) * (K @ K)
    M[kind == TRANS, :3, 3] = axis[kind == TRANS] * v[kind == TRANS, None]
    return M


_RUNS: dict = {}  # (chain id, the run's parameter values, s, e) -> folded run: planners call `forward` thousands of times per x


def _constant_run(chain: Chain, x: np.ndarray, s: int, e: int):
    """Product P of steps s..e−1 (no joint among them) and each step's axis and origin in the
    run's first frame (memoised per parameter vector, read-only)."""
    p = chain.param[s:e]
    key = (id(chain), (np.where(p >= 0, x[p], 0.0) if x.size else np.zeros(p.size)).tobytes(), s, e)  # the run's own values: a fit that holds
    hit = _RUNS.get(key)  # them fixed (most joints, most rounds of a model selection) folds the run once
    if hit is not None and hit[0] is chain:
        return hit[1]
    M = _step_matrices(chain, x, s, e)
    P = np.eye(4)
    ax_local, org_local = np.empty((e - s, 3)), np.empty((e - s, 3))
    for k in range(e - s):
        ax_local[k], org_local[k] = P[:3, :3] @ chain.axis[s + k], P[:3, 3]
        P = P @ M[k]
    if len(_RUNS) > 4096:
        _RUNS.clear()
    out = (P, ax_local, org_local)
    for a in out:
        a.setflags(write=False)
    _RUNS[key] = (chain, out)
    return out


_PLANS: dict = {}  # chain id -> (chain, `_plan`)


def _plan(chain: Chain) -> list[tuple[int, int, int, tuple[int, int] | None]]:
    """`Chain.runs` with what `_walk` asks of each run, worked out once per chain: (s, e, its joint
    or −1, and for a rotation about a frame axis the two columns it mixes, else None)."""
    hit = _PLANS.get(id(chain))
    if hit is not None and hit[0] is chain:
        return hit[1]
    out = []
    for s, e in chain.runs():
        a, ji, principal = chain.axis[s], int(chain.joint[s]), None
        if ji >= 0 and chain.kind[s] == ROT and np.count_nonzero(a) == 1 and np.count_nonzero(a == 1.0) == 1:
            principal = ((1, 2), (2, 0), (0, 1))[int(np.flatnonzero(a == 1.0)[0])]
        out.append((s, e, ji, principal))
    if len(_PLANS) > 256:
        _PLANS.clear()
    _PLANS[id(chain)] = (chain, out)
    return out


_WALKS: dict = {}  # (chain id, x, q, want) bytes -> `_walk` arrays (read-only)


def walk(chain: Chain, x: np.ndarray, q: np.ndarray, want_jacobian: bool):
    """`_walk`, memoised on its inputs (a fit and the diagnosis ask for the same chain at the
    same parameters several times).  Returned arrays are read-only."""
    x = np.asarray(x, dtype=float)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    key = (id(chain), x.tobytes(), q.shape, q.tobytes(), want_jacobian)
    hit = _WALKS.get(key)
    if hit is None or hit[0] is not chain:
        res = _walk(chain, x, q, want_jacobian)
        for a in res[:2]:
            a.setflags(write=False)
        if len(_WALKS) >= 8:
            _WALKS.pop(next(iter(_WALKS)))
        _WALKS[key] = hit = (chain, res)
    return hit[1]


def _walk(chain: Chain, x: np.ndarray, q: np.ndarray, want_jacobian: bool):
    """Walk the chain: end rotations (N,3,3), positions (N,3) and, with `want_jacobian`, the
    frame at the start of every run: a list of (s, e, R (N,3,3), t (N,3))."""
    n, nj = q.shape
    if nj != chain.n_joints or x.shape != (chain.n_params,):
        raise ValueError(f"{nj} joint values per row and {x.shape[0]} parameters do not fit a chain of "
                         f"{chain.n_joints} joints and {chain.n_params} parameters")
    starts = [] if want_jacobian else None
    steps_local = []  # each run's own transform: (R (3,3) or (N,3,3), t (3,) or (N,3))
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    for s, e, ji, principal in _plan(chain):
        if want_jacobian:
            starts.append((s, e, T[:, :3, :3].copy(), T[:, :3, 3].copy()))
        if ji < 0:
            P = _constant_run(chain, x, s, e)[0]
            T = T @ P
            steps_local.append((P[:3, :3], P[:3, 3]))
            continue
        a = chain.axis[s]
        v = q[:, ji] + _value(chain, x, s)
        if chain.kind[s] == TRANS:
            T[:, :3, 3] += (T[:, :3, :3] @ a) * v[:, None]
            steps_local.append((np.eye(3), a * v[:, None]))
            continue
        if want_jacobian:
            steps_local.append((_rodrigues(a, v), np.zeros(3)))
        if principal is not None:
            # rotation about a frame axis: two column operations instead of a 3×3 product
            i, j = principal
            c, sn = np.cos(v)[:, None], np.sin(v)[:, None]
            ci, cj = T[:, :3, i].copy(), T[:, :3, j]
            T[:, :3, i] = c * ci + sn * cj
            T[:, :3, j] = c * cj - sn * ci
        else:
            T[:, :3, :3] = T[:, :3, :3] @ _rodrigues(a, v)
    if want_jacobian:
        # the end point in each run's start frame, walking back from the end: p_s = R_run p_(s+1) + t_run
        # (exact where the rest is constant, e.g. a tool's own rotations about the tip give exact zeros)
        ps = np.zeros((n, 3))
        for i in range(len(starts) - 1, -1, -1):
            Rr, tr = steps_local[i]
            ps = (ps @ Rr.T if Rr.ndim == 2 else np.einsum("nij,nj->ni", Rr, ps)) + tr
            starts[i] = starts[i] + (ps,)
    return T[:, :3, :3], T[:, :3, 3], starts


def forward(chain: Chain, x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """End-frame rotations (N,3,3) and positions (N,3) m in the chain's start frame."""
    R, p, _ = walk(chain, x, q, False)
    return R.copy(), p.copy()


def _local(chain: Chain, x: np.ndarray, s: int, e: int) -> tuple[np.ndarray, np.ndarray]:
    """Axes and origins (k,3) of steps s..e−1 in the frame at the run's start."""
    if chain.joint[s] >= 0:
        return chain.axis[s:s + 1], np.zeros((1, 3))
    _, ax, org = _constant_run(chain, x, s, e)
    return ax, org


CHUNK = 4096  # rows per block of the Jacobian's columns (≈ 100 kB per temporary)


def _derivatives(chain: Chain, x: np.ndarray, p: np.ndarray, starts: list, select: np.ndarray, index: np.ndarray,
                 width: int, angular: bool):
    """Position (N,3,width) and, with `angular`, orientation derivatives of the steps where
    `select` (S,) holds, each into column `index[step]`.  Per run, in the run's start frame
    {s}: a rotation about axis a through o moves p by a × (p_s − o), a translation by a; one
    batched product with R_s brings a run's columns to the chain's frame.

    The columns are built parameter-major, (width, N, 3), and returned as (N, 3, width) views:
    each parameter's column is then one contiguous write, which keeps the cost linear in N
    when the Jacobian no longer fits in cache (writing a column of an (N, 3, width) array
    touches every cache line of it)."""
    n = p.shape[0]
    Jp = np.zeros((width, n, 3))
    Jw = np.zeros((width, n, 3)) if angular else None
    runs = []
    for s, e, Rs, ts, ps in starts:
        k = np.flatnonzero(select[s:e])
        if k.size:
            ax, org = _local(chain, x, s, e)
            runs.append((ax[k], org[k], chain.kind[s + k] == ROT, index[s + k], Rs, ps))
    if not runs:
        return Jp.transpose(1, 2, 0), (Jw.transpose(1, 2, 0) if angular else None)
    # every run's steps at once, each with its run's start frame: the same numbers in one pass
    A, O, rot, idx = (np.concatenate([r[i] for r in runs]) for i in range(4))
    which = np.concatenate([np.full(len(r[0]), i) for i, r in enumerate(runs)])
    Rs_all, ps_all = np.stack([r[4] for r in runs]), np.stack([r[5] for r in runs])
    for lo in range(0, n, CHUNK):  # row blocks: every temporary stays in cache, cost linear in N
        sl = slice(lo, min(lo + CHUNK, n))
        R = Rs_all[:, sl][which]  # (K,n,3,3): each step's run start frame
        _add(Jp, idx, sl, _run_columns(A, O, rot, R, ps_all[:, sl][which]))  # (K,n,3) in the chain's frame
        if angular and rot.any():
            _add(Jw, idx[rot], sl, _rotate(R[rot], A[rot][:, None, :]))
    return Jp.transpose(1, 2, 0), (Jw.transpose(1, 2, 0) if angular else None)


def _run_columns(A: np.ndarray, O: np.ndarray, rot: np.ndarray, Rs: np.ndarray, ps: np.ndarray) -> np.ndarray:
    """(k,n,3) d end point / d value of k steps (axes A, origins O (k,3) in their run's start frame, `rot`
    rotation or translation), the run's start frame Rs (n,3,3) and the end point in it ps (n,3) — or each
    step's own, (k,n,3,3) and (k,n,3)."""
    d = (ps[None, :, :] if ps.ndim == 2 else ps) - O[:, None, :]  # (k,n,3)
    a = A[:, None, :]
    cr = np.stack([a[..., 1] * d[..., 2] - a[..., 2] * d[..., 1],
                   a[..., 2] * d[..., 0] - a[..., 0] * d[..., 2],
                   a[..., 0] * d[..., 1] - a[..., 1] * d[..., 0]], axis=-1)
    return _rotate(Rs, np.where(rot[:, None, None], cr, a))


def turns_after(chain: Chain, x: np.ndarray, q: np.ndarray, after: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """d end position / d angle (N,3,K) of K rotations at angle 0 about `axes` (K,3), each given in the frame
    after step `after[k]` (a joint step: a run of its own): the column a chain with that rotation inserted
    there as a joint (a virtual joint held at 0, e.g. a tree's lateral compliance) has — the same numbers,
    since a turn by 0 leaves every frame as it is."""
    x = np.asarray(x, dtype=float)
    _, p, starts = walk(chain, x, q, True)
    at = {s: (Rs, ps) for s, _e, Rs, _t, ps in starts}
    out = np.zeros((len(after), p.shape[0], 3))
    for k, (s, a) in enumerate(zip(after, axes)):
        Rs, ps = at[int(s) + 1]
        A = (np.asarray(a, float) / np.linalg.norm(a))[None, :]
        out[k] += _run_columns(A, np.zeros((1, 3)), np.array([True]), Rs, ps)[0]
    return out.transpose(1, 2, 0)


def _rotate(Rs: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rs[n] @ v[k, n] for Rs (N,3,3) or (k,N,3,3) and v (k,N,3) or (k,1,3): three streaming multiply-adds
    (a batched 3×3 product per row is several times slower at this shape)."""
    R = Rs[None] if Rs.ndim == 3 else Rs
    return R[..., 0] * v[..., 0:1] + R[..., 1] * v[..., 1:2] + R[..., 2] * v[..., 2:3]


def _add(J: np.ndarray, idx: np.ndarray, rows: slice, cols: np.ndarray) -> None:
    """J[idx, rows] += cols (parameter-major), also where several steps share a parameter
    (their effects add up): in place, one contiguous block per column."""
    for j, c in zip(idx, cols):
        J[j, rows] += c


def _columns(chain: Chain, columns: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(which steps, into which column) of the parameter derivatives: each parameter into its own
    column, or with `columns` ((n_params,) int: each parameter's column, −1 none) only those asked for."""
    if columns is None:
        return chain.param >= 0, chain.param
    c = np.asarray(columns, int)
    idx = np.where(chain.param >= 0, c[chain.param], -1) if c.size else np.full(chain.n_steps, -1)
    return idx >= 0, idx


def jacobian(chain: Chain, x: np.ndarray, q: np.ndarray, angular: bool = False, width: int | None = None,
             columns: np.ndarray | None = None):
    """End positions (N,3) and d position / d x (N,3,P); with `angular`, also the end frame's
    rotations (N,3,3) and its angular derivative (N,3,P): the world-frame rotation vector δω
    with δR = [δω]× R.  `width` ≥ P allocates that many columns (a caller's parameters appended
    after the chain's stay zero) instead of copying into a wider array afterwards.  `columns`
    ((P,) int, −1 none): only the parameters a solver moves, each into its column (the same numbers)."""
    x = np.asarray(x, dtype=float)
    R, p, starts = walk(chain, x, q, True)
    w = chain.n_params if width is None else width
    Jp, Jw = _derivatives(chain, x, p, starts, *_columns(chain, columns), w, angular)
    if not angular:
        return p.copy(), Jp
    return p.copy(), Jp, R.copy(), Jw


def joint_jacobian(chain: Chain, x: np.ndarray, q: np.ndarray, angular: bool = False):
    """End positions (N,3) and d position / d q (N,3,n_joints); with `angular`, also the
    angular part (N,3,n_joints)."""
    x = np.asarray(x, dtype=float)
    _, p, starts = walk(chain, x, q, True)
    Jq, Jw = _derivatives(chain, x, p, starts, chain.joint >= 0, chain.joint, chain.n_joints, angular)
    if not angular:
        return p.copy(), Jq
    return p.copy(), Jq, Jw


def jacobians(chain: Chain, x: np.ndarray, q: np.ndarray, width: int, joints: np.ndarray,
              columns: np.ndarray | None = None):
    """One walk for both: end positions (N,3), d position / d x (N,3,width) and d position / d q
    (N,3,n_joints) of the joint columns in `joints` (the others zero) — for measurement models whose
    extra parameters act through a few joint values (a tree's physics terms).  `columns` as in `jacobian`."""
    x = np.asarray(x, dtype=float)
    _, p, starts = walk(chain, x, q, True)
    Jp, _ = _derivatives(chain, x, p, starts, *_columns(chain, columns), width, False)
    select = np.isin(chain.joint, np.asarray(joints, int)) & (chain.joint >= 0)
    Jq, _ = _derivatives(chain, x, p, starts, select, chain.joint, chain.n_joints, False)
    return p.copy(), Jp, Jq


def frames(chain: Chain, x: np.ndarray, q: np.ndarray, marks: list[int]) -> np.ndarray:
    """World poses (N, len(marks), 4, 4) after each step index in `marks` (for drawing)."""
    x = np.asarray(x, dtype=float)
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n = q.shape[0]
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    out = np.zeros((n, len(marks), 4, 4))
    where = {m: i for i, m in enumerate(marks)}
    for s in range(chain.n_steps):
        v = _value(chain, x, s) + (q[:, chain.joint[s]] if chain.joint[s] >= 0 else 0.0)
        v = np.broadcast_to(np.asarray(v, float), (n,))
        if chain.kind[s] == CONST:
            T = T @ chain.const[s]
        elif chain.kind[s] == ROT:
            M = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
            M[:, :3, :3] = _rodrigues(chain.axis[s], v)
            T = T @ M
        else:
            T = T.copy()
            T[:, :3, 3] += (T[:, :3, :3] @ chain.axis[s]) * v[:, None]
        if s in where:
            out[:, where[s]] = T
    return out


def unit(i: int) -> np.ndarray:
    """The i-th frame axis (0 x, 1 y, 2 z)."""
    return _UNIT[i]
