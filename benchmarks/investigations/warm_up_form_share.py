"""How much of the independent generator's warm-up (a2, d4 × (1 + α(1 − e^(−t/300 s)))) each warm-up form
leaves, on its noise-free campaign (seed 0, the benchmark's targets), in units of the noise σ at 4× the
effect's MDS (12σ ⊥ the geometry in all): the norm of the signature ⊥ (geometry + the form's columns).

Forms: growth of every link, of the long links alone (J2's a and J4's d here: `pipeline.diagnose.library.thermal.link_groups`),
and one growth per link (a, d of J2, J3, J4, J5: four columns — beyond the campaign's detectable size at the
plausible growth, so not in the library); time forms linear and 1 − e^(−t/τ), τ on the library's grid.
Computed with the generator's own kinematics (finite differences of its link lengths), not the library's.

Usage: ``python benchmarks/investigations/warm_up_form_share.py``
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))

import independent_touch as it  # noqa: E402


def main() -> None:
    nom, tru = it.default_arms()
    tg = it.plan(nom, it.stepped_block(), m=120, seed=1)
    sigma = it.run(nom, tru, tg, (), seed=0).along_normal_noise_sigma_m
    form = it.Effect("thermal_growth", 1.0, {"tau_s": 300.0})
    eff = it.Effect(form.kind, 4 * it.mds(nom, tru, tg, form, sigma), form.where)
    c0 = it.run(nom, tru, tg, (), seed=0, noise=0.0)
    c1 = it.run(nom, tru, tg, (eff,), seed=0, noise=0.0)
    ax = c0.table["axis"]
    rows = np.arange(ax.size)
    q = c0.truth_joint_q
    S = it.tip(tru, c1.truth_joint_q)[rows, ax] - it.tip(tru, q)[rows, ax]
    t = np.asarray(c0.table["time_since_start_s"], float)
    T = float(t.max())
    U, sv, _ = np.linalg.svd(it.geometric_jacobian(tru, q, ax), full_matrices=False)
    U = U[:, sv > sv[0] * 1e-9]

    def perp(X):
        return X - U @ (U.T @ X)

    Sp = perp(S[:, None])[:, 0]
    h = 1e-6
    base = it.tip(tru, q)[rows, ax]
    cols = np.array([(it.tip(tru, q, np.where(np.arange(6) == i, 1 + h, 1.0)[None].repeat(q.shape[0], 0))[rows, ax]
                      - base) / h for i in range(6)]).T  # (n, 6): L·∂p/∂L of each joint's a and d
    active = np.linalg.norm(cols, axis=0) > 1e-6

    def left(X):
        Q, _ = np.linalg.qr(perp(X))
        return np.linalg.norm(Sp - Q @ (Q.T @ Sp)) / sigma

    print(f"campaign T = {T:.0f} s, τ = 300 s; effect ⊥ geometry {np.linalg.norm(Sp) / sigma:.1f}σ")
    print("time form    every link  long links  per link")
    for name, w in ([("linear", t)] + [(f"τ = T/{1 / f:g}", 1 - np.exp(-t / (f * T))) for f in (0.125, 0.25, 0.5, 1.0)]
                    + [("τ = 300 s", 1 - np.exp(-t / 300.0))]):
        print(f"{name:12s} {left((w * cols.sum(1))[:, None]):8.2f}σ {left((w * cols[:, [1, 3]].sum(1))[:, None]):9.2f}σ"
              f" {left(w[:, None] * cols[:, active]):8.2f}σ")


if __name__ == "__main__":
    main()
