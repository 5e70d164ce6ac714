"""The held-out price of one more column: on CLEAN independent-generator campaigns (no effect), the grouped
cross-validated RMS of geometry + one library column (joint_coupling J2->J3, J3->J2, joint_scale J3) over that of
the geometry alone, same folds as the diagnosis (5 folds of time blocks of 5 contacts).  Above 1 is what modelling
that effect costs out of sample even when its size is right: the variance of a column nearly collinear with the
geometry.  On the block alone and on the two-station campaign (`independent_touch.two_stations`).

Usage: ``python benchmarks/investigations/coupling_cv_cost.py [--seeds 100,108,119,137,101,102]``
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))

import independent_touch as it  # noqa: E402

from pipeline.diagnose.inference import resampling  # noqa: E402
from pipeline.diagnose.library.term import pick  # noqa: E402
from pipeline.diagnose.adapters.touch import touch_adapter  # noqa: E402
from pipeline.identify.least_squares import fit, kfold_indices  # noqa: E402
from pipeline.systems import arc_welder as aw  # noqa: E402

COLUMNS = (("joint_coupling", "J2->J3"), ("joint_coupling", "J3->J2"), ("joint_scale", "J3"))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="100,108,119,137,101,102")
    a = ap.parse_args()
    nom, tru = it.default_arms()
    print("campaign        seed  " + "  ".join(f"{n}@{loc}" for n, loc in COLUMNS))
    for label, jig in (("two stations", it.two_stations()), ("block", it.stepped_block())):
        targets = it.plan(nom, jig, m=120, seed=1)
        for seed in map(int, a.seeds.split(",")):
            table = it.run(nom, tru, targets, (), seed=seed, jig=jig).table
            model = aw.TouchModel(aw.nominal_arm())
            f = fit(model, table)
            Jf = model.jacobian(f.x, table)[:, :, f.free].reshape(-1, int(f.free.sum()))
            r = f.residuals_after.reshape(-1)
            ad = touch_adapter(model, table, 2e-5, None, 1e-4)
            folds = kfold_indices(r.size, 5, 0, resampling.time_blocks(ad.time_s, 5))
            base = resampling.rms(resampling.holdout(Jf, r, folds))
            ratios = []
            for name, loc in COLUMNS:
                (S,) = ad.signatures(f.x, table, (pick(ad.library, name, loc),))
                ratios.append(resampling.rms(resampling.holdout(np.hstack([Jf, S.reshape(r.size, -1)]), r, folds)) / base)
            print(f"{label:14s} {seed:5d}  " + "  ".join(f"{x:20.3f}" for x in ratios))


if __name__ == "__main__":
    main()
