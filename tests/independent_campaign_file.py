"""The independent generator (`independent_touch`) on a campaign robocal planned: the plan file read as plain JSON
(`schemas/campaign.schema.json`: faces, approach joints, search joint rates, in execution order — no robocal code),
and which of its contacts the true arm touches.  Angles rad, lengths m."""

from __future__ import annotations

import numpy as np
from independent_touch import Arm, Targets, run

from pipeline.models.jig import Jig, stepped_block


def touching(nominal: Arm, truth: Arm, targets: Targets, jig: Jig | None = None, travel_m: float = 0.085) -> np.ndarray:
    """(m,) bool: the targets whose search reaches its face on the true arm within `travel_m` of search, without
    effects or noise (a search that has not touched by then grazes its face or misses it: a controller reports
    "no contact" and the campaign goes on without it)."""
    ok = np.zeros(targets.face.size, bool)
    for i in range(ok.size):
        one = Targets(targets.face[i:i + 1], targets.q_a[i:i + 1], targets.dq[i:i + 1])
        try:
            q = run(nominal, truth, one, (), n=1, jig=jig, noise=0.0).truth_joint_q[0]
        except RuntimeError:
            continue
        k = np.argmax(np.abs(one.dq[0]))
        ok[i] = 0 < (q[k] - one.q_a[0, k]) / one.dq[0, k] <= travel_m
    return ok


def from_campaign(doc: dict, jig: Jig | None = None) -> Targets:
    """The targets of a campaign file (`schemas/campaign.schema.json`, read here as plain JSON): each
    measurement's face, approach joints and search joint rate, in execution order."""
    ids = [f.id for f in (jig or stepped_block()).faces]
    rows = doc["measurements"]
    return Targets(np.array([ids.index(r["face"]) for r in rows], int),
                   np.array([r["approach_joints_rad"] for r in rows], float),
                   np.array([r["search_joint_rate_rad_per_m"] for r in rows], float))


def take(targets: Targets, idx: np.ndarray) -> Targets:
    return Targets(targets.face[idx], targets.q_a[idx], targets.dq[idx])
