"""Where to put a second station so that a J2→J3 coupling and a J2 encoder eccentricity can be told apart:
for each candidate offset of a copy of the stepped block (`independent_touch.two_stations(dx, dz)`), the
principal angle between the two signatures ⊥ the free geometry on a clean campaign (seed 100, the
benchmark's targets) — the gate's test (`bench_diagnose_independent.coupling_share`; cos² > 0.95:
indistinguishable) — and J2's range.  A property of the campaign: no effect is injected.

Usage: ``python benchmarks/investigations/station_angle.py``
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

root = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(root / "tests"), str(root / "benchmarks")]

import bench_diagnose_independent as bench  # noqa: E402
import independent_touch as it  # noqa: E402

STATIONS = ((0.3, 0.0), (0.25, -0.2), (0.0, 0.3), (-0.2, 0.3), (0.35, -0.3), (0.4, -0.2), (0.2, -0.3), (0.45, -0.35))


def main() -> None:
    nom, tru = it.default_arms()
    for label, jig in [("block alone", it.stepped_block())] + [(f"station {dx:+.2f}, {dz:+.2f} m", it.two_stations(dx, dz))
                                                               for dx, dz in STATIONS]:
        targets = it.plan(nom, jig, m=120, seed=1)
        c = it.run(nom, tru, targets, (), seed=100, jig=jig)
        s = bench.coupling_share(c.table)
        print(f"{label:24s} J2 range {np.ptp(c.table['joint_positions'][:, 1]):.2f} rad  cos² {s['cos2']:.3f}  "
              f"angle {s['principal_angle_deg']:5.1f}°  {'indistinguishable' if s['indistinguishable'] else ''}")


if __name__ == "__main__":
    main()
