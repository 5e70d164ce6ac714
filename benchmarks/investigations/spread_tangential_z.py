"""Per-run p1, p2 estimate, std, dof of the tangential refit on spread campaigns (docs/guide/diagnose.md, "Confidence intervals").
usage: PYTHONPATH=.:benchmarks python benchmarks/investigations/spread_tangential_z.py FIRST_SEED_OFFSET N MODES MULT > out.jsonl
MODES: comma list of full, img, rep, print, noimg, zero (which simulator noise sources are on).
Each record also has cr2_over_iid: the refit's CR2 std of p1, p2 over the i.i.d. (σ-based) std of the same design."""
import sys, json

import numpy as np
import bench_diagnose_scanner as b
from spread_cases import tangential_cases
from pipeline.diagnose import confirm
from pipeline.diagnose import scanner as ds
from pipeline.diagnose.diagnose import Settings, diagnose
from pipeline.simulate import scorbot_scanner as ss
from pipeline.simulate.effects import parse_effect
from pipeline.systems import scorbot_scanner as sc

NOISE = {"full": ss.Noise(), "img": ss.Noise(repeatability_3sigma_m=0, print_sigma_m=0),
         "rep": ss.Noise(image_px=0, print_sigma_m=0), "print": ss.Noise(image_px=0, repeatability_3sigma_m=0),
         "noimg": ss.Noise(image_px=0), "zero": ss.Noise(scale=0.0)}
_crs = confirm.cluster_robust_std
LAST: dict = {}


def _wrap(A, r, cl, working=None):
    """CR2 as the diagnosis computes it, and the ratio of its std to the i.i.d. std of the last two columns."""
    s, d = _crs(A, r, cl, working)
    cn = np.linalg.norm(A, axis=0)
    cn[cn == 0] = 1
    B = np.linalg.pinv((A / cn).T @ (A / cn)) / np.outer(cn, cn)
    sig = np.sqrt(r @ r / max(r.size - A.shape[1], 1))
    LAST["ratio"] = list(s[-2:] / (sig * np.sqrt(np.diag(B)[-2:])))
    return s, d


confirm.cluster_robust_std = _wrap  # diagnose.py calls it as confirm.cluster_robust_std

def run(specs, seed, noise):
    c = ss.Campaign(poses=20, corners=8, seed=seed, capture_speed_rad_s=0.1, spread=True)
    try:
        sim, tab = ss.simulate_in_memory(b.ARM, b.ARM, b.truth(), c, noise=noise,
                                         effects=tuple(parse_effect(s) for s in specs), plan_cache=b.CACHE)
    except RuntimeError:
        return None
    tab = ds.add_context(tab, sim.stream_t_ns, sim.stream_q)
    m = sc.ScannerModel(arm=b.ARM)
    return diagnose(m, tab, adapter=ds.adapter(m, tab), settings=Settings(n_boot=0))

start, n, modes, mult = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3].split(","), float(sys.argv[4])
out = []
for seed, sp, val in tangential_cases(start, n, mult):
    for mode in modes:
        d = run([sp], seed, NOISE[mode])
        f = [f for f in d["findings"] if f["effect"] == "tangential_distortion"]
        g = d["geometry"]
        rec = {"seed": seed, "mode": mode, "val": val, "gauge": b.in_fitted_gauge("tangential_distortion", d),
               "found": bool(f), "cr2_over_iid": LAST.pop("ratio", None), "others": [x["effect"] + "@" + x["location"] for x in d["findings"] if x["effect"] != "tangential_distortion"],
               "geom": dict(zip(g["names"], g["x"]))}
        if f:
            rec["pars"] = [{k: p[k] for k in ("value", "std", "dof", "ci95")} for p in f[0]["parameters"]]
        out.append(rec)
        print(json.dumps(rec), flush=True)
