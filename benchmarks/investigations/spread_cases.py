"""The spread-tangential investigations' cases: the first plannable spread campaigns from seed 30000 + start and
tangential distortion at `mult` × each campaign's MDS (as `bench_diagnose_scanner.spread_block` injects it)."""

from __future__ import annotations

from collections.abc import Iterator

import bench_diagnose_scanner as b


def tangential_cases(start: int, n: int, mult: float, corners: int = 8) -> Iterator[tuple[int, str, float]]:
    """(seed, effect spec, injected p1 = p2 in 1/m) for seeds 30000+start … 30000+start+n−1 that can be
    planned and where tangential distortion is identifiable."""
    for seed in range(30_000 + start, 30_000 + start + n):
        d0 = b.run_spread([], seed, corners)
        if d0 is None:
            continue
        mds = b.mds_of(d0).get(("tangential_distortion", "camera"))
        if mds is None:
            continue
        sp, val = b.spec("tangential_distortion", "camera", mult * mds)
        yield seed, sp, val
