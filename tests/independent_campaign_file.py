"""The independent generator (`independent_touch`) on a campaign robocal planned: the plan file read as plain JSON
(`schemas/campaign.schema.json`: faces, approach joints, search joint rates, in execution order — no robocal code),
and which of its contacts the true arm touches.  Angles rad, lengths m."""

from __future__ import annotations

import numpy as np
from independent_jig import Block as Jig
from independent_jig import stepped_block
from independent_touch import Arm, Targets, run


def touching(nominal: Arm, truth: Arm, targets: Targets, jig: Jig | None = None, travel_m: float = 0.085) -> np.ndarray:
    """(m,) bool: the targets whose search reaches its face on the true arm within `travel_m` of search, without
    effects or noise (a search that has not touched by then grazes its face or misses it: a controller reports
    "no contact" and the campaign goes on without it)."""
    ok = np.zeros(targets.face.size, bool)
    _touching(nominal, truth, targets, jig, travel_m, np.arange(ok.size), ok)
    return ok


def _touching(nominal, truth, targets, jig, travel_m, idx, ok) -> None:
    """`touching` on the contacts `idx`, run together (each contact's search is its own: no effects, no noise);
    a batch where one search does not settle is halved until that contact stands alone (and is left out)."""
    part = take(targets, idx)
    try:
        q = run(nominal, truth, part, (), n=idx.size, jig=jig, noise=0.0).truth_joint_q
    except RuntimeError:
        if idx.size > 1:
            for half in np.array_split(idx, 2):
                _touching(nominal, truth, targets, jig, travel_m, half, ok)
        return
    rows = np.arange(idx.size)
    k = np.argmax(np.abs(part.dq), axis=1)
    ok[idx] = (lambda t: (0 < t) & (t <= travel_m))((q[rows, k] - part.q_a[rows, k]) / part.dq[rows, k])


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
