"""Spread-campaign tangential p1, p2: z of the diagnosis (CR2 + BM dof) vs rows whitened by the pixel-noise
covariance (∂P/∂px pseudo-inverse; one GLS step from the refit; CR2 + BM and i.i.d. std on the whitened rows).
usage: PYTHONPATH=.:benchmarks python THIS SEED_OFFSET N img,full MULT > w.jsonl  (summary: spread_tangential_whitened_summary.py)"""
import sys, json
import numpy as np
import bench_diagnose_scanner as b
from spread_cases import tangential_cases
from pipeline.diagnose.inference import augmented
from pipeline.diagnose.adapters import scanner as ds
from pipeline.diagnose import Settings, diagnose
from pipeline.simulate import scorbot_scanner as ss
from pipeline.simulate.effects import parse_effect
from pipeline.systems import scorbot_scanner as sc

NOISE = {"full": ss.Noise(), "img": ss.Noise(repeatability_3sigma_m=0, print_sigma_m=0)}
_crs = augmented.cluster_robust_std
LAST = {}
def _wrap(A, r, cl, working=None):
    s, d = _crs(A, r, cl, working)
    LAST.update(A=A, r=r, cl=cl, s=s, d=d)
    return s, d
augmented.cluster_robust_std = _wrap

start, n, modes, mult = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3].split(","), float(sys.argv[4])
for seed, sp, val in tangential_cases(start, n, mult):
    for mode in modes:
        c = ss.Campaign(poses=20, corners=8, seed=seed, capture_speed_rad_s=0.1, spread=True)
        sim, tab = ss.simulate_in_memory(b.ARM, b.ARM, b.truth(), c, noise=NOISE[mode], effects=(parse_effect(sp),), plan_cache=b.CACHE)
        tab = ds.add_context(tab, sim.stream_t_ns, sim.stream_q)
        m = sc.ScannerModel(arm=b.ARM)
        LAST.clear()
        d = diagnose(m, tab, adapter=ds.adapter(m, tab), settings=Settings(n_boot=0))
        f = [f for f in d["findings"] if f["effect"] == "tangential_distortion"]
        if not f or "A" not in LAST:
            continue
        A, r, cl = LAST["A"], LAST["r"], LAST["cl"]
        nrow = A.shape[0] // 3
        ctx = ds.context(m, np.array(d["geometry"]["x"]), tab)
        D = ctx["dP_dpx"]  # (n,3,2)
        # whitening: for rank-2 cov D Dᵀ, W = pinv(D) maps the 3-vector to 2 pixel-equivalent residuals
        W = np.linalg.pinv(D)  # (n,2,3)
        Aw = np.einsum("nij,njk->nik", W, A.reshape(nrow, 3, -1)).reshape(2 * nrow, -1)
        rw = np.einsum("nij,nj->ni", W, r.reshape(nrow, 3)).reshape(-1)
        clw = np.repeat(np.asarray(cl).reshape(nrow, 3)[:, 0], 2)
        cn = np.linalg.norm(Aw, axis=0); cn[cn == 0] = 1
        step = -(np.linalg.lstsq(Aw / cn, rw, rcond=None)[0] / cn)
        sw, dw = _crs(Aw, rw + Aw @ step, clw)
        sig = np.sqrt(np.sum((rw + Aw @ step) ** 2) / max(rw.size - Aw.shape[1], 1))
        B = np.linalg.pinv((Aw / cn).T @ (Aw / cn)) / np.outer(cn, cn)
        siid = sig * np.sqrt(np.diag(B))
        out = {"seed": seed, "mode": mode}
        for j in (0, 1):
            p = f[0]["parameters"][j]
            scale = p["std"] / LAST["s"][-2 + j]
            t = val * b.in_fitted_gauge("tangential_distortion", d)
            est_w = p["value"] + step[-2 + j] * scale
            out[f"p{j+1}"] = {"z_cr2": (p["value"] - t) / p["std"], "dof": p["dof"],
                              "z_w_cr2": (est_w - t) / (sw[-2 + j] * scale), "dof_w": float(dw[-2 + j]),
                              "z_w_iid": (est_w - t) / (siid[-2 + j] * scale)}
        print(json.dumps(out), flush=True)
