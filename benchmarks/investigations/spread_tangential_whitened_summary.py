"""Summary of spread_tangential_whitened.py records (usage: python THIS w.jsonl …)."""
import json, sys
import numpy as np
from scipy import stats
R = [json.loads(l) for f in sys.argv[1:] for l in open(f)]
for m in ("img", "full"):
    Q = [r for r in R if r["mode"] == m]
    for p in ("p1", "p2"):
        line = f"{m} {p} n={len(Q)}:"
        for k, dk in (("z_cr2", "dof"), ("z_w_cr2", "dof_w"), ("z_w_iid", None)):
            z = np.array([r[p][k] for r in Q])
            q = stats.t.ppf(.975, [r[p][dk] for r in Q]) if dk else 1.96
            line += f" | {k}: mean {z.mean():+.2f} sd {z.std(ddof=1):.2f} cover {100*np.mean(abs(z) <= q):.0f} %"
        print(line)
