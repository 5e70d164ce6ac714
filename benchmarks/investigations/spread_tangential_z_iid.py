"""Summary of spread_tangential_z.py records: CR2 vs i.i.d. std of p1, p2 (usage: python THIS a.jsonl …)."""
import json, sys
import numpy as np
from scipy import stats
R = [json.loads(l) for f in sys.argv[1:] for l in open(f)]
for m in [m for m in ("img", "full", "rep", "print", "zero") if any(r["mode"] == m for r in R)]:
    Q = [r for r in R if r["mode"] == m and r["found"] and r["cr2_over_iid"]]
    for j, nm in enumerate(("p1", "p2")):
        t = np.array([r["val"] * r["gauge"] for r in Q]); v = np.array([r["pars"][j]["value"] for r in Q])
        s = np.array([r["pars"][j]["std"] for r in Q]); dof = np.array([r["pars"][j]["dof"] for r in Q])
        ratio = np.array([r["cr2_over_iid"][j] for r in Q]); si = s / ratio
        z, zi = (v - t) / s, (v - t) / si
        cv = np.std(np.log(ratio), ddof=1)
        print(f"{m} {nm} n={len(Q)}: CR2/iid-std median {np.median(ratio):.2f} [{ratio.min():.2f}, {ratio.max():.2f}], "
              f"sd log ratio {cv:.2f} (BM dof {np.median(dof):.0f} implies ~{1/np.sqrt(2*np.median(dof)):.2f}); "
              f"z_CR2 mean {z.mean():+.2f} sd {z.std(ddof=1):.2f} cover(t) {100*np.mean(abs(z) <= stats.t.ppf(.975, dof)):.0f} % | "
              f"z_iid mean {zi.mean():+.2f} sd {zi.std(ddof=1):.2f} cover(1.96) {100*np.mean(abs(zi) <= 1.96):.0f} %")
