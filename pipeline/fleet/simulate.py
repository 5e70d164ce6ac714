"""A simulated fleet of touch-sensing arc-welding robots, calibrated monthly: each robot its own
truth (errors of the paper's size), optional changes of one parameter over the months (a step from
a given month, a linear drift), recordings written as `ARCHIVE/<robot_id>/<YYYY-MM>/campaign.mcap`
with the robot's identity and the campaign's date in the recording.  The truth of every campaign
goes to `ARCHIVE/fleet.truth.json` (never into a recording)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Change:
    """`param` of robot `robot` (index) changes by `value` (SI) from `month` on (step) or by `value`
    per month (drift, month 1 = no change)."""

    robot: int
    param: str
    value: float
    kind: str = "step"  # step | drift
    month: int = 1


@dataclass(frozen=True)
class FleetSpec:
    robots: int = 5
    months: int = 12
    contacts: int = 40
    seed: int = 0
    start_year: int = 2026
    start_month: int = 1
    rate_hz: float = 25.0  # controller rate of the logged encoder stream (small files)
    changes: tuple[Change, ...] = field(default_factory=tuple)

    def robot_id(self, i: int) -> str:
        return f"arc-{i + 1:02d}"

    def month_start(self, m: int) -> datetime:
        """Start of calibration month m (1-based): the 1st of the month, 06:00 UTC."""
        k = self.start_month - 1 + m - 1
        return datetime(self.start_year + k // 12, k % 12 + 1, 1, 6, tzinfo=timezone.utc)


def true_vector(base: np.ndarray, names: list[str], changes: list[Change], m: int) -> np.ndarray:
    """The truth of month m (1-based) from the robot's month-1 truth."""
    x = base.copy()
    for c in changes:
        i = names.index(c.param)
        if c.kind == "step" and m >= c.month:
            x[i] += c.value
        elif c.kind == "drift":
            x[i] += c.value * (m - 1)
    return x


def simulate_fleet(archive: Path, spec: FleetSpec = FleetSpec()) -> dict:
    """Write every campaign of the fleet; returns the truth document (also written)."""
    from pipeline.models.jig import stepped_block
    from pipeline.recording.schemas import META_CAMPAIGN, META_FIXTURE, META_ROBOT
    from pipeline.recording.writer import write_campaign
    from pipeline.simulate.arc_welder import Campaign, Noise, simulate
    from pipeline.systems import arc_welder as aw

    archive = Path(archive)
    nominal, jig = aw.nominal_arm(), stepped_block()
    names = nominal.parameter_names()
    for c in spec.changes:
        if c.param not in names:
            raise ValueError(f"unknown parameter {c.param!r}")
    truth: dict = {"spec": {k: v for k, v in spec.__dict__.items() if k != "changes"},
                   "changes": [c.__dict__ for c in spec.changes], "robots": {}}
    for r in range(spec.robots):
        rid = spec.robot_id(r)
        base = aw.random_truth(nominal, np.random.default_rng([spec.seed, r, 1])).vector()
        changes = [c for c in spec.changes if c.robot == r]
        truth["robots"][rid] = {"parameter_names": names, "months": []}
        for m in range(1, spec.months + 1):
            when = spec.month_start(m)
            true = nominal.with_vector(true_vector(base, names, changes, m))
            campaign = Campaign(contacts=spec.contacts, seed=spec.seed * 100_003 + r * 1009 + m, rate_hz=spec.rate_hz,
                                start_ns=int(when.timestamp()) * 1_000_000_000)
            sim = simulate(nominal, true, jig, campaign, Noise())
            path = archive / rid / when.strftime("%Y-%m") / "campaign.mcap"
            path.parent.mkdir(parents=True, exist_ok=True)
            meta = {META_ROBOT: nominal.to_dict(), META_FIXTURE: jig.to_dict(),
                    META_CAMPAIGN: {"system": aw.SYSTEM, "simulated": True, "robot_id": rid,
                                    "contacts": campaign.contacts, "controller_rate_hz": campaign.rate_hz,
                                    "search_speed_m_s": campaign.search_speed_m_s,
                                    "approach_offset_m": campaign.approach_offset_m}}
            write_campaign(path, meta, (sim.stream_t_ns, sim.stream_q, [j.name for j in nominal.joints]),
                           list(aw.contact_messages(sim)))
            truth["robots"][rid]["months"].append({"month": m, "start": when.isoformat(),
                                                   "recording": path.relative_to(archive).as_posix(),
                                                   "x": true.vector().tolist()})
    (archive / "fleet.truth.json").write_text(json.dumps(truth, indent=1) + "\n")
    return truth
