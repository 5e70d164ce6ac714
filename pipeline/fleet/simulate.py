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


def campaign_path(archive: Path, spec: FleetSpec, r: int, m: int) -> Path:
    """ARCHIVE/ROBOT/YYYY-MM/campaign.mcap of robot r (0-based), month m (1-based)."""
    return Path(archive) / spec.robot_id(r) / spec.month_start(m).strftime("%Y-%m") / "campaign.mcap"


def simulate_campaign(archive: Path, spec: FleetSpec, r: int, m: int) -> dict:
    """Write robot r's campaign of month m; its truth entry.  A campaign whose latched joints fall
    outside the joint limits is re-planned with the next seed (as an integrator would re-teach it)."""
    from pipeline.models.jig import stepped_block
    from pipeline.recording.schemas import META_CAMPAIGN, META_FIXTURE, META_ROBOT
    from pipeline.recording.writer import write_campaign
    from pipeline.simulate.arc_welder import Campaign, Noise, simulate
    from pipeline.systems import arc_welder as aw

    nominal, jig = aw.nominal_arm(), stepped_block()
    names = nominal.parameter_names()
    rid, when = spec.robot_id(r), spec.month_start(m)
    base = aw.random_truth(nominal, np.random.default_rng([spec.seed, r, 1])).vector()
    true = nominal.with_vector(true_vector(base, names, [c for c in spec.changes if c.robot == r], m))
    for attempt in range(20):
        campaign = Campaign(contacts=spec.contacts, seed=spec.seed * 100_003 + r * 1009 + m * 31 + attempt * 7919,
                            rate_hz=spec.rate_hz, start_ns=int(when.timestamp()) * 1_000_000_000)
        sim = simulate(nominal, true, jig, campaign, Noise())
        if np.all((sim.contact_q >= nominal.lower) & (sim.contact_q <= nominal.upper)):
            break
    path = campaign_path(archive, spec, r, m)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {META_ROBOT: nominal.to_dict(), META_FIXTURE: jig.to_dict(),
            META_CAMPAIGN: {"system": aw.SYSTEM, "simulated": True, "robot_id": rid,
                            "contacts": campaign.contacts, "controller_rate_hz": campaign.rate_hz,
                            "search_speed_m_s": campaign.search_speed_m_s,
                            "approach_offset_m": campaign.approach_offset_m}}
    write_campaign(path, meta, (sim.stream_t_ns, sim.stream_q, [j.name for j in nominal.joints]),
                   list(aw.contact_messages(sim)))
    return {"robot_id": rid, "month": m, "start": when.isoformat(), "seed": campaign.seed,
            "recording": path.relative_to(archive).as_posix(), "x": true.vector().tolist()}


def simulate_fleet(archive: Path, spec: FleetSpec = FleetSpec(), workers: int = 1, force: bool = False) -> dict:
    """Write every campaign of the fleet (`workers` processes); returns the truth document (also written).
    Existing recordings (and the truth) are replaced only with `force`, each kept as NAME.bak."""
    from concurrent.futures import ProcessPoolExecutor

    from pipeline.recording.output import check_output, claim_output, generated
    from pipeline.systems import arc_welder as aw

    archive = Path(archive)
    names = aw.nominal_arm().parameter_names()
    for c in spec.changes:
        if c.param not in names:
            raise ValueError(f"unknown parameter {c.param!r}")
    jobs = [(archive, spec, r, m) for r in range(spec.robots) for m in range(1, spec.months + 1)]
    truth_path = check_output(archive / "fleet.truth.json", "truth", force)  # before anything is written:
    for job in jobs:  # a file robocal did not write is never replaced, a recording only with --force
        check_output(campaign_path(*job), force=force)
    for p in [truth_path] + [campaign_path(*job) for job in jobs]:
        claim_output(p, "truth" if p == truth_path else "recording", force)
    from pipeline.progress import Ticker

    tick = Ticker("simulate fleet", total=len(jobs), unit="campaigns")
    if workers > 1:
        with ProcessPoolExecutor(workers) as pool:
            done = []
            for d in pool.map(simulate_campaign, *zip(*jobs)):
                done.append(d)
                tick(f"{d['robot_id']} month {d['month']}")
    else:
        done = []
        for j in jobs:
            done.append(simulate_campaign(*j))
            tick(str(campaign_path(*j).relative_to(archive)))
    tick.done()
    truth: dict = {"spec": {k: v for k, v in spec.__dict__.items() if k != "changes"},
                   "changes": [c.__dict__ for c in spec.changes], "parameter_names": names,
                   "robots": {spec.robot_id(r): [d for d in done if d["robot_id"] == spec.robot_id(r)]
                              for r in range(spec.robots)}}
    truth_path.write_text(json.dumps(generated(truth), indent=1) + "\n")
    return truth
