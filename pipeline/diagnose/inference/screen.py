"""Steps 2–3 of the diagnosis: the linearised problem at the geometric solution, the model of the
noise it is tested against, and the gate + selection of candidate terms iterated with that model.

- `Problem`: the free geometric Jacobian Jf (n·k, p) m per unit, the residual r (n·k,) m, the
  residual degrees of freedom, σ (m) of the geometry fit and each candidate's signature S (n·k, k_e)
  m per unit — rows flattened measurement-major;
- `noise_model`: with pose clusters (`Adapter.cluster`), the random-effects whitener of the cluster
  errors (`clustered.cluster_whitener`); the within-cluster noise is estimated from the residuals of
  the maximal model (geometry + every candidate) so that a term cannot inflate the noise it is
  tested against and hide in it;
- `select`: the gate (`gate.gate`) and the forward selection (`stepwise.forward_select`), the gate's σ
  (and, with clusters, the whitener: feasible GLS) re-estimated from the residuals after the
  accepted terms until the accepted set no longer changes; with clusters, a finding must also pass
  the cluster-robust sign-flip test (Holm) or it is dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.diagnose.inference.clustered import (
    Whitener,
    cluster_whitener,
    measurement_whitener,
    noise_components,
    sign_flip_elimination,
)
from pipeline.diagnose.inference.gate import gate, sigma_given
from pipeline.diagnose.inference.projection import orthonormal, project_out
from pipeline.diagnose.inference.stepwise import conditional_steps, forward_select


@dataclass
class Problem:
    """The linearised problem at the geometric solution (module docstring)."""

    n: int
    k: int
    free_names: list[str]
    Jf: np.ndarray
    r: np.ndarray
    dof: int
    sigma: float
    lib: list
    S: list[np.ndarray]

    @property
    def n_free(self) -> int:
        return self.Jf.shape[1]


def problem(model, table, f, ad) -> Problem:
    """The `Problem` of geometry fit `f` (`identify.least_squares.Fit`) under adapter `ad`."""
    n, k = f.residuals_after.shape
    nk = n * k
    free_names = [nm for nm, b in zip(f.names, f.free) if b]
    Jf = model.jacobian(f.x, table)[:, :, f.free].reshape(nk, -1)
    r = f.residuals_after.reshape(nk)
    S3 = ad.signatures(f.x, table, tuple(ad.library))
    return Problem(n, k, free_names, Jf, r, nk - int(f.free.sum()), f.sigma, ad.library,
                   [sg.reshape(nk, -1) for sg in S3])


@dataclass
class Noise:
    """The noise model of the tests: per-row cluster ids `cl` (None: independent rows), the cluster
    basis `Zc`, the per-measurement noise shape `M` (k×k) with its sources `src` and components `nm`,
    the whitener `W` (None: unwhitened), σ_within of the maximal model `sigma_noise` (m)."""

    Zc: np.ndarray | None = None
    cl: np.ndarray | None = None
    M: object = None
    eff_rows: object = None
    nm: object = None
    W: Whitener | None = None
    sigma_noise: float | None = None
    src: list | None = None


def noise_model(ad, x: np.ndarray, p: Problem) -> Noise:
    """The `Noise` of the module docstring; updates `p.dof` to the dimensions that carry noise."""
    nz = Noise()
    if ad.cluster is None:
        return nz
    n, k, nk = p.n, p.k, p.n * p.k
    Zb = (ad.cluster_basis(x) if ad.cluster_basis is not None
          else np.broadcast_to(np.eye(k), (n, k, k)))
    nz.Zc = np.asarray(Zb, float).reshape(nk, -1)
    nz.cl = np.repeat(np.asarray(ad.cluster), k)
    if ad.noise_shape is not None:
        r_max = project_out(p.r[:, None], orthonormal(np.hstack([p.Jf] + p.S)))[:, 0]
        src = ad.noise_shape(x)
        nz.src = list(src) if isinstance(src, (list, tuple)) else [src]
        nz.nm = noise_components(r_max, nz.Zc, nz.cl, nz.src)
        nz.M, nz.eff_rows = measurement_whitener(nz.src, nz.nm.variances), nz.nm.effective_rows
        W_max = cluster_whitener(r_max, nz.Zc, nz.cl, p.n_free + sum(sg.shape[1] for sg in p.S), pre=nz.M,
                                 effective_rows=nz.eff_rows)
        nz.sigma_noise = None if W_max is None else W_max.sigma_within
    nz.W = cluster_whitener(p.r, nz.Zc, nz.cl, p.n_free, pre=nz.M, effective_rows=nz.eff_rows)
    if nz.W is not None:  # residual degrees of freedom: only the dimensions that carry noise
        p.dof = nz.W.n_effective - p.n_free
    return nz


@dataclass
class Selection:
    """The gate of every candidate, the testable ones (indices into the library) with their projected
    signatures `Sp` and tolerances, the selection's `steps`, the `accepted` library indices, the
    (whitened) Jacobian and residual the tests ran on, and the sign-flip p-values / dropped findings."""

    gates: list
    testable: list[int]
    Sp: list[np.ndarray]
    tols: list[float]
    steps: list
    Jf_w: np.ndarray
    r_w: np.ndarray
    accepted: list[int]
    robust_p: dict
    dropped: list[int]

    def restrict(self, p: Problem, chosen: list[int]) -> None:
        """Re-derive the steps (F and Holm p given the others) of a changed accepted set."""
        self.steps = conditional_steps(self.r_w, self.Sp, p.dof, [self.testable.index(i) for i in chosen],
                                       self.tols, len(self.testable))
        self.accepted = [self.testable[st.index] for st in self.steps]


def select(p: Problem, nz: Noise, s) -> Selection:
    """Gate and selection iterated with the noise model (module docstring); `s` the diagnosis
    `Settings` (alpha, max_terms, sign_flips, seed).  Updates `nz.W` (feasible GLS)."""
    gate_cache: dict = {}  # the gate's σ-free part (unwhitened problem: the same in every screen)
    Jf, r, S, lib = p.Jf, p.r, p.S, p.lib

    def screen(W: Whitener | None, prior: list[int] | None = None):
        """Gate and selection, on the whitened problem when W is given; the gate's σ is the residual σ
        after the `prior` accepted terms (the geometry-only σ when there are none)."""
        if W is None:
            Jw, rw, Sw, sw = Jf, r, S, p.sigma
        else:
            Jw = W(Jf)
            rw = project_out(W(r)[:, None], orthonormal(Jw))[:, 0]
            Sw = [W(sg) for sg in S]
            # the noise, not the geometry-only residual (which holds any term): from the maximal model
            sw = nz.sigma_noise or W.sigma_within
        if prior and (W is None or nz.sigma_noise is None):
            sw = sigma_given(rw, Jw, [Sw[i] for i in prior], p.dof)
        gs = gate(lib, Sw, Jw, p.free_names, sw, s.alpha, gate_cache if W is None else None)
        tst = [i for i, g in enumerate(gs) if g.identifiable]
        sp = [gs[i].projected for i in tst]
        tl = [lib[i].tolerance for i in tst]
        return gs, tst, sp, tl, forward_select(rw, sp, p.dof, s.alpha, tl, s.max_terms), Jw, rw

    W = nz.W
    gates, testable, Sp, tols, steps, Jf_w, r_w = screen(W)
    accepted = [testable[st.index] for st in steps]
    for _ in range(3):
        if not accepted:
            break
        if W is not None:
            Dacc = np.hstack([Jf] + [S[i] for i in accepted])
            coef, *_ = np.linalg.lstsq(Dacc, r, rcond=None)
            W2 = cluster_whitener(r - Dacc @ coef, nz.Zc, nz.cl, Dacc.shape[1], pre=nz.M, effective_rows=nz.eff_rows)
            W = W2 if W2 is not None else W
        gates, testable, Sp, tols, steps, Jf_w, r_w = screen(W, accepted)
        new = [testable[st.index] for st in steps]
        done = sorted(new) == sorted(accepted)
        accepted = new
        if done:
            break
    nz.W = W
    sel = Selection(gates, testable, Sp, tols, steps, Jf_w, r_w, accepted, {}, [])
    # with clusters, the F tests rest on the whitener's model of the error within a pose; a finding
    # must also pass the cluster-robust sign-flip test (Holm), or it is dropped
    if W is not None and accepted and s.sign_flips:
        kept, sel.robust_p, sel.dropped = sign_flip_elimination(W, r, Jf_w, S, accepted, nz.cl, len(testable),
                                                                s.alpha, s.sign_flips, s.seed)
        sel.accepted = kept
        if sel.dropped:
            sel.restrict(p, kept)
    return sel
