"""The executable campaign file (`schemas/campaign.schema.json`): write and read, validated.

`robocal plan SYSTEM --out CAMPAIGN.json` writes it; `robocal simulate SYSTEM --campaign`
(and `robocal device-sim --campaign`) executes it.  Reading checks the schema and the
consistency a robot needs (joint counts, unit search directions, faces of the fixture) and
fails with one line naming the file and the measurement.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import RobocalError
from pipeline.models.jig import Jig
from pipeline.plan.touch import TouchPool, face_margin
from pipeline.simulate.arc_welder import Campaign

KIND, VERSION = "robocal.campaign", 1
AXES = "xyz"


def touch_document(system: str, arm, jig: Jig, sel: TouchPool, campaign: Campaign, margin_m: float,
                   stage: int = 1, stages: int = 1, candidates: np.ndarray | None = None) -> dict[str, Any]:
    """Campaign document of the selected touch candidates, in execution order."""
    cand = np.arange(sel.face.size) if candidates is None else np.asarray(candidates)
    rows = []
    for i in range(sel.face.size):
        f = jig.faces[int(sel.face[i])]
        rows.append({"index": i, "candidate": int(cand[i]), "face": f.id, "axis": f.axis,
                     "coordinate": float(f.coordinate), "approach_joints_rad": sel.q_approach[i].tolist(),
                     "search_direction": (-f.normal).tolist(), "search_joint_rate_rad_per_m": sel.dq[i].tolist(),
                     "predicted_contact_m": sel.target[i].tolist(), "predicted_travel_m": float(sel.travel[i]),
                     "edge_distance_m": float(sel.edge_distance[i])})
    return {"kind": KIND, "version": VERSION, "system": system, "measurement": "touch",
            "joint_names": [j.name for j in arm.joints], "stage": stage, "stages": stages,
            "planning_model": arm.to_dict(), "fixture": jig.to_dict(),
            "controller": {"standoff_m": campaign.approach_offset_m, "search_speed_m_s": campaign.search_speed_m_s,
                           "search_travel_m": campaign.search_travel_m, "rate_hz": campaign.rate_hz,
                           "joint_speed_rad_s": campaign.joint_speed_rad_s, "dwell_s": campaign.dwell_s},
            "margin_m": margin_m, "face_margins_m": {f.id: list(face_margin(f, margin_m)) for f in jig.faces},
            "measurements": rows}


@dataclass
class TouchCampaign:
    """A touch campaign read from a file: arrays in execution order (SI, jig frame)."""

    path: str
    doc: dict
    face_id: list[str]
    axis: np.ndarray  # (n,) 0/1/2
    coordinate: np.ndarray  # (n,) m
    q_approach: np.ndarray  # (n, n_joints) rad
    dq: np.ndarray  # (n, n_joints) rad per m
    direction: np.ndarray  # (n, 3) unit, jig frame
    campaign: Campaign  # controller settings

    @property
    def n(self) -> int:
        return len(self.face_id)


def write_document(out: Path, doc: dict) -> None:
    """The plan / campaign JSON, robocal's generator its first key (`recording.output`: robocal may
    replace it later; it never replaces a file it did not create)."""
    from pipeline.recording.output import check_output, generated
    from pipeline.stages.artefacts import write_json

    check_output(out, "plan")
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    write_json(out, generated(doc))


def load_document(path: str | Path) -> dict:
    """A campaign file as JSON, checked against schemas/campaign.schema.json (one-line RobocalError
    naming the file and the first offending measurement)."""
    from pipeline.recording.schemas import validator

    try:
        doc = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise RobocalError(f"{path}: no such campaign file") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise RobocalError(f"{path}: not a JSON campaign file ({e})") from None
    except RecursionError:
        raise RobocalError(f"{path}: not a campaign file (JSON nested deeper than Python can read)") from None
    except OSError as e:
        raise RobocalError(f"{path}: cannot read ({type(e).__name__}: {e.strerror or e})") from None
    try:
        errors = sorted(validator("campaign").iter_errors(doc), key=lambda e: list(e.absolute_path))
    except RecursionError:
        raise RobocalError(f"{path}: not a campaign file (JSON nested too deep to check)") from None
    if errors:
        where = "/".join(str(p) for p in errors[0].absolute_path).replace("measurements/", "measurement ") or "document"
        raise RobocalError(f"{path}: {where}: {errors[0].message} (schemas/campaign.schema.json)")
    return doc


def read(path: str | Path, system: str | None = None, n_joints: int | None = None,
         jig: Jig | None = None) -> TouchCampaign:
    """Read and check a touch campaign file (one-line RobocalError naming file and measurement)."""
    path = str(path)
    doc = load_document(path)
    if system is not None and doc["system"] != system:
        raise RobocalError(f"{path}: is a {doc['system']} campaign, not {system}")
    if doc["measurement"] != "touch":
        raise RobocalError(f"{path}: measurement type {doc['measurement']!r}: only touch campaigns run on {system}")
    rows = doc["measurements"]
    faces = {f.id: f for f in jig.faces} if jig is not None else None
    nj = n_joints if n_joints is not None else len(doc["joint_names"])
    for r in rows:
        i = r["index"]
        if "face" not in r:
            raise RobocalError(f"{path}: measurement {i}: a touch measurement needs face, approach_joints_rad, ...")
        for k in ("approach_joints_rad", "search_joint_rate_rad_per_m"):
            v = np.asarray(r[k], float)
            if v.shape != (nj,) or not np.all(np.isfinite(v)):
                raise RobocalError(f"{path}: measurement {i}: {k} must be {nj} finite numbers (got {r[k]!r})")
        d = np.asarray(r["search_direction"], float)
        if not np.all(np.isfinite(d)) or abs(np.linalg.norm(d) - 1) > 1e-6:
            raise RobocalError(f"{path}: measurement {i}: search_direction must be a unit vector (got {r['search_direction']!r})")
        if faces is not None:
            f = faces.get(r["face"])
            if f is None:
                raise RobocalError(f"{path}: measurement {i}: face {r['face']!r} is not on the fixture "
                                   f"({', '.join(faces)})")
            if f.axis != r["axis"] or abs(f.coordinate - r["coordinate"]) > 1e-12:
                raise RobocalError(f"{path}: measurement {i}: face {r['face']!r} fixes {f.axis} = {f.coordinate} m "
                                   f"on the fixture, the campaign says {r['axis']} = {r['coordinate']}")
    c = doc.get("controller", {})
    base = Campaign()
    camp = Campaign(contacts=len(rows), approach_offset_m=float(c.get("standoff_m", base.approach_offset_m)),
                    search_speed_m_s=float(c.get("search_speed_m_s", base.search_speed_m_s)),
                    search_travel_m=float(c.get("search_travel_m", base.search_travel_m)),
                    rate_hz=float(c.get("rate_hz", base.rate_hz)),
                    joint_speed_rad_s=float(c.get("joint_speed_rad_s", base.joint_speed_rad_s)),
                    dwell_s=float(c.get("dwell_s", base.dwell_s)))
    samples = expected_samples(camp)
    if not samples <= MAX_SAMPLES:
        raise RobocalError(f"{path}: controller: {len(rows)} contacts at these settings make ~{samples:.3g} encoder "
                           f"samples, more than robocal runs in one campaign ({MAX_SAMPLES:.0e})")
    return TouchCampaign(path=path, doc=doc, face_id=[r["face"] for r in rows],
                         axis=np.array([AXES.index(r["axis"]) for r in rows], int),
                         coordinate=np.array([r["coordinate"] for r in rows], float),
                         q_approach=np.array([r["approach_joints_rad"] for r in rows], float).reshape(len(rows), nj),
                         dq=np.array([r["search_joint_rate_rad_per_m"] for r in rows], float).reshape(len(rows), nj),
                         direction=np.array([r["search_direction"] for r in rows], float), campaign=camp)


MAX_SAMPLES = 5e7  # encoder samples of one executed campaign (~2.4 GB of joint positions: beyond is damage)


def expected_samples(c: Campaign) -> float:
    """About how many encoder samples running campaign `c` logs (moves at most π at joint speed, two
    dwells, a search over the travel at search speed, per contact)."""
    with np.errstate(all="ignore"):
        per_contact = 2 * c.dwell_s + c.search_travel_m / c.search_speed_m_s + 2 * (np.pi / c.joint_speed_rad_s * 1.5 + 0.3)
        return float(c.contacts * per_contact * c.rate_hz)


def concat(parts: list[TouchCampaign]) -> TouchCampaign:
    """Campaigns run back to back (the stages of a staged campaign), with the first one's controller."""
    if len(parts) == 1:
        return parts[0]
    doc = dict(parts[0].doc, stage=max(p.doc["stage"] for p in parts),
               measurements=[m for p in parts for m in p.doc["measurements"]])
    return TouchCampaign(path=", ".join(p.path for p in parts), doc=doc, face_id=[f for p in parts for f in p.face_id],
                         **{k: np.concatenate([getattr(p, k) for p in parts])
                            for k in ("axis", "coordinate", "q_approach", "dq", "direction")},
                         campaign=parts[0].campaign)


def from_pool(system: str, arm, jig: Jig, pool: TouchPool, campaign: Campaign = Campaign(), margin_m: float = 0.0,
              stage: int = 1, stages: int = 1) -> TouchCampaign:
    """A `TouchCampaign` of planned candidates without a file (benchmarks, tests)."""
    doc = touch_document(system, arm, jig, pool, campaign, margin_m, stage, stages)
    return TouchCampaign(path="<memory>", doc=doc, face_id=[jig.faces[int(f)].id for f in pool.face],
                         axis=pool.axis.copy(), coordinate=np.array([jig.faces[int(f)].coordinate for f in pool.face]),
                         q_approach=pool.q_approach.copy(), dq=pool.dq.copy(),
                         direction=np.array([-jig.faces[int(f)].normal for f in pool.face]).reshape(-1, 3),
                         campaign=replace(campaign, contacts=int(pool.face.size)))


def read_pose(path: str | Path, system: str, joint_names: list[str]) -> np.ndarray:
    """Joint configurations (n, len(joint_names)) rad of a `measurement: pose` campaign of `system`,
    columns reordered to `joint_names` (the campaign must name exactly those joints); one-line errors."""
    path = str(path)
    doc = load_document(path)
    if doc["system"] != system or doc["measurement"] != "pose":
        raise RobocalError(f"{path}: is a {doc['system']} {doc['measurement']} campaign, not a {system} pose campaign")
    names = list(doc["joint_names"])
    if sorted(names) != sorted(joint_names):
        raise RobocalError(f"{path}: joint_names {names} do not match the robot's joints {list(joint_names)}")
    order = [names.index(j) for j in joint_names]
    out = []
    for m in doc["measurements"]:
        q = np.asarray(m.get("joints_rad", []), float)
        if q.shape != (len(names),) or not np.all(np.isfinite(q)):
            raise RobocalError(f"{path}: measurement {m['index']}: joints_rad must be {len(names)} finite numbers")
        out.append(q[order])
    return np.array(out).reshape(-1, len(names))
