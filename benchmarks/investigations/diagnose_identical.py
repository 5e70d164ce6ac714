"""Is a refactoring of `pipeline/diagnose/` behaviour-preserving?  `diagnosis.json` (without `elapsed_s`) of the four
bundled recordings (`robocal diagnose … --bootstrap 10`) and of eight independent-generator campaigns (clean, a2/d4
warm-up, J2→J3 coupling, dent at 4× MDS; seeds 100, 101), computed by two source trees and compared.

Usage (two commits as trees, e.g. before and after a split):
    git archive A | tar -x -C /tmp/a;  git archive B | tar -x -C /tmp/b
    python benchmarks/investigations/diagnose_identical.py /tmp/a /tmp/b
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

RECORDINGS = ("arc-welder-touch", "arc-welder-touch-pb", "delta-tracker", "scorbot-scanner")
SIMULATED = r'''
import sys, json
sys.path.insert(0, "{src}/tests")
import independent_touch as it
from pipeline.diagnose import Settings, diagnose
from pipeline.systems import arc_welder as aw
nom, tru = it.default_arms()
tg = it.plan(nom, it.stepped_block(), m=120, seed=1)
sigma = it.run(nom, tru, tg, (), seed=0).along_normal_noise_sigma_m
res = {{}}
for name, eff in [("clean", None), ("thermal", it.Effect("thermal_growth", 1.0, {{"tau_s": 300.0}})),
                  ("coupling", it.Effect("coupling", 1.0, {{"pair": (1, 2)}})),
                  ("dent", it.Effect("dent", 1.0, {{"face": 1, "centre": (0.15, 0.1), "radius": 0.03}}))]:
    if eff is not None:
        eff = it.Effect(eff.kind, 4 * it.mds(nom, tru, tg, eff, sigma), eff.where)
    for seed in (100, 101):
        c = it.run(nom, tru, tg, () if eff is None else (eff,), seed=seed)
        d = diagnose(aw.TouchModel(aw.nominal_arm()), c.table,
                     settings=Settings(n_boot=10, repeatability_3sigma_m=1e-4))
        d.pop("elapsed_s", None)
        res[f"{{name}}_{{seed}}"] = d
print(json.dumps(res, sort_keys=True, default=str))
'''


def outputs(src: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for rec in RECORDINGS:
            d = Path(tmp) / rec
            subprocess.run([sys.executable, "-m", "pipeline", "diagnose", str(src / "recordings" / f"{rec}.mcap"),
                            "--out", str(d), "--bootstrap", "10"], env=env, cwd=tmp, capture_output=True, check=True)
            doc = json.loads((d / "diagnosis.json").read_text())
            doc.pop("elapsed_s", None)
            out[rec] = doc
        r = subprocess.run([sys.executable, "-c", SIMULATED.format(src=src)], env=env, cwd=tmp, capture_output=True,
                           text=True, check=True)
    out.update(json.loads(r.stdout))
    return out


def main() -> None:
    a, b = (outputs(Path(p).resolve()) for p in sys.argv[1:3])
    for k in a:
        print(f"{k:24s} {'identical' if a[k] == b.get(k) else 'DIFFERENT'}")
    sys.exit(0 if a == b else 1)


if __name__ == "__main__":
    main()
