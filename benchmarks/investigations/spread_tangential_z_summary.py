import json, sys
import numpy as np
from scipy import stats
recs = [json.loads(l) for f in sys.argv[1:] for l in open(f)]
modes = sorted({r["mode"] for r in recs}, key=lambda m: ["full","img","rep","print","noimg","zero"].index(m))
for mode in modes:
    R = [r for r in recs if r["mode"] == mode]
    found = [r for r in R if r["found"]]
    print(f"== {mode}: {len(found)}/{len(R)} found")
    for j, nm in enumerate(("p1", "p2")):
        t = np.array([r["val"] * r["gauge"] for r in found])
        v = np.array([r["pars"][j]["value"] for r in found]); s = np.array([r["pars"][j]["std"] for r in found])
        dof = np.array([r["pars"][j]["dof"] or np.inf for r in found])
        z = (v - t) / s
        q = stats.t.ppf(0.975, dof)
        cov = np.mean(np.abs(z) <= q)
        rel = (v - t) / t
        print(f"  {nm}: mean z {z.mean():+.2f} (se {z.std(ddof=1)/np.sqrt(len(z)):.2f}), sd z {z.std(ddof=1):.2f}, "
              f"cover {cov*100:.0f} %, dof median {np.median(dof):.1f} [{dof.min():.1f},{dof.max():.1f}], "
              f"mean rel bias {rel.mean()*100:+.1f} % (sd {rel.std(ddof=1)*100:.1f} %), median std/truth {np.median(s/t)*100:.1f} %, "
              f"sd(rel)/median(std/t) {rel.std(ddof=1)/np.median(s/t):.2f}")
