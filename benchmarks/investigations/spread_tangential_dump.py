"""Dump the joint refit's problem of tangential runs on spread campaigns, for offline study of std estimators.
usage: PYTHONPATH=.:benchmarks python benchmarks/investigations/spread_tangential_dump.py FIRST_SEED_OFFSET N MODE MULT OUTDIR
Per run OUTDIR/<seed>_<mode>_<mult>.npz: A (N,p) refit design (free columns, p1/p2 last), r (N,) residual, cl (N,) pose,
src_px (n,3,2) ∂P/∂pixel, src_print (n,3,1), corner (n,3) nominal corner, Z (n,3,6) pose basis, truth (2,) p1/p2 in the fitted gauge, est (2,),
std (2,), dof (2,) as reported (CR2 + Bell–McCaffrey)."""
import os
import sys

import numpy as np
import bench_diagnose_scanner as b
from spread_cases import tangential_cases
from pipeline.diagnose.inference import augmented
from pipeline.diagnose.adapters import scanner as ds
from pipeline.diagnose import Settings, diagnose
from pipeline.simulate import scorbot_scanner as ss
from pipeline.simulate.effects import parse_effect
from pipeline.systems import scorbot_scanner as sc

NOISE = {"full": ss.Noise(), "img": ss.Noise(repeatability_3sigma_m=0, print_sigma_m=0),
         "rep": ss.Noise(image_px=0, print_sigma_m=0), "print": ss.Noise(image_px=0, repeatability_3sigma_m=0)}

_crs = augmented.cluster_robust_std
LAST: dict = {}


def _keep(A, r, cl, working=None):
    LAST.update(A=A, r=r, cl=cl)
    return _crs(A, r, cl, working)


augmented.cluster_robust_std = _keep
start, n, mode, mult, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], float(sys.argv[4]), sys.argv[5]
os.makedirs(out, exist_ok=True)
for seed, sp, val in tangential_cases(start, n, mult):
    c = ss.Campaign(poses=20, corners=8, seed=seed, capture_speed_rad_s=0.1, spread=True)
    sim, tab = ss.simulate_in_memory(b.ARM, b.ARM, b.truth(), c, noise=NOISE[mode], effects=(parse_effect(sp),),
                                     plan_cache=b.CACHE)
    tab = ds.add_context(tab, sim.stream_t_ns, sim.stream_q)
    m = sc.ScannerModel(arm=b.ARM)
    LAST.clear()
    d = diagnose(m, tab, adapter=ds.adapter(m, tab), settings=Settings(n_boot=0))
    f = [f for f in d["findings"] if f["effect"] == "tangential_distortion"]
    if not f or [x for x in d["findings"] if x["effect"] != "tangential_distortion"]:
        print(seed, "skipped", [x["effect"] for x in d["findings"]], flush=True)
        continue
    x = np.array(d["geometry"]["x"])
    ctx = ds.context(m, x, tab)
    P = f[0]["parameters"]
    np.savez(f"{out}/{seed}_{mode}_{mult:g}.npz", A=LAST["A"], r=LAST["r"], cl=LAST["cl"], src_px=ctx["dP_dpx"],
             corner=np.asarray(tab["corner"], float),
             src_print=ds.stripe_directions(tab), Z=ds.pose_basis(m, x, tab),
             truth=np.full(2, val * b.in_fitted_gauge("tangential_distortion", d)),
             est=np.array([p["value"] for p in P]), std=np.array([p["std"] for p in P]),
             dof=np.array([p["dof"] or np.inf for p in P]))
    print(seed, "ok", flush=True)
