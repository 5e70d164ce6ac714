"""Several recordings of one robot → one recording (`robocal run A.mcap B.mcap …`, `calibrate`).

Each source recording becomes a *session*: its rows are copied unchanged (times, joints,
measurements) in the order given, and the campaign lists the sessions (``sessions``: source path,
sha256, rows, instrument) and how the instrument frame is shared (``registration``: ``shared`` —
one instrument frame for all sessions — or ``per-recording`` — each session its own frame,
`pipeline.measurements.sessions`).  Coincidence groups and planes keep their names; a name two
sessions both use gets the session's file stem as prefix (``front:hole_0``) so two placements never
share a socket point.  The sources must be recordings of the same robot, chain and measurement type.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from pipeline.errors import RobocalError
from pipeline.recording.schemas import META_CAMPAIGN, META_URDF

REGISTRATIONS = ("shared", "per-recording")


def _check_same(recs: list) -> None:
    first = recs[0]
    m0, c0 = first.metadata.get(META_URDF) or {}, first.metadata.get(META_CAMPAIGN) or {}
    if c0.get("system") != "urdf":
        raise RobocalError(f"{first.path}: several recordings are calibrated together for URDF robots only")
    for rec in recs[1:]:
        m, c = rec.metadata.get(META_URDF) or {}, rec.metadata.get(META_CAMPAIGN) or {}
        for what, a, b in (("system", c.get("system"), c0.get("system")), ("measurement type", c.get("measure"),
                           c0.get("measure")), ("chain root", m.get("root"), m0.get("root")),
                           ("chain tip", m.get("tip"), m0.get("tip")), ("robot description", m.get("urdf"), m0.get("urdf")),
                           ("robot_id", c.get("robot_id"), c0.get("robot_id"))):
            if a != b:
                shown = "differs" if what == "robot description" else f"{a!r}, but {first.path} has {b!r}"
                raise RobocalError(f"{rec.path}: {what} {shown}: one calibration takes recordings of one robot and "
                                   "measurement type")


MERGED = "merge"  # the header's library note of a merged recording (derived: calibrate re-merges it)


def merge(paths: list[Path], out: Path, registration: str = "shared") -> int:
    """Write the merged recording of `paths` to `out` (module docstring); returns rows written."""
    from pipeline.evaluate.apply import instrument_of
    from pipeline.importers.recording import write_urdf_recording
    from pipeline.models import urdf
    from pipeline.recording.reader import read_recording
    from pipeline.stages.artefacts import sha256_file
    from pipeline.systems.urdf_robot import channel_of

    if registration not in REGISTRATIONS:
        raise RobocalError(f"--registration {registration!r}: expected shared or per-recording")
    recs = [read_recording(p) for p in paths]
    _check_same(recs)
    c0 = recs[0].metadata[META_CAMPAIGN]
    measure = c0.get("measure")
    key = {"plane": "plane", "coincidence": "group"}.get(measure)
    seen: dict[str, int] = {}
    for rec in recs:
        for n in {str(m.get(key, "")) for m in rec.messages[channel_of(measure)]} if key else ():
            seen[n] = seen.get(n, 0) + 1
    if registration == "shared" and len({instrument_of(r.metadata[META_CAMPAIGN]) for r in recs} - {None}) > 1:
        raise RobocalError(f"{paths[0]} …: the recordings name different instruments; one shared registration cannot "
                           "serve them (--registration per-recording)")
    rows: dict[str, list] = {}
    sessions, planes, distances = [], {}, []
    for path, rec in zip(paths, recs):
        camp = rec.metadata[META_CAMPAIGN]
        rename = (lambda n, stem=Path(path).stem: f"{stem}:{n}" if seen.get(n, 0) > 1 else n)
        msgs = rec.messages[channel_of(measure)]
        for m in msgs:
            for k, v in m.items():
                rows.setdefault(k, []).append(rename(str(v)) if k == key else v)
        for p in camp.get("planes", []):
            planes[rename(str(p["name"]))] = {**p, "name": rename(str(p["name"]))}
        for d in camp.get("distances", []):
            distances.append({**d, "a": rename(str(d["a"])), "b": rename(str(d["b"]))})
        sessions.append({"source": str(path), "sha256": sha256_file(path), "rows": len(msgs),
                         "instrument": instrument_of(camp)})
    table = {k: np.asarray(v, object if k == key else None) for k, v in rows.items()}
    campaign = {k: v for k, v in c0.items() if k not in ("system", "measure", "joint_names", "planes", "distances",
                                                          "source_files", "import_warnings")}
    campaign |= {"sessions": sessions, "registration": registration}
    if measure == "point":
        campaign["n_targets"] = max(int(r.metadata[META_CAMPAIGN].get("n_targets", 1)) for r in recs)
    if planes:
        campaign["planes"] = list(planes.values())
    if distances:
        campaign["distances"] = distances
    m0 = recs[0].metadata[META_URDF]
    desc = urdf.parse(m0["urdf"], m0["root"], m0["tip"], source=f"{paths[0]}: metadata robocal.urdf")
    desc = replace(desc, source=m0.get("source", desc.source))
    return write_urdf_recording(out, desc, measure, campaign, table, origin=MERGED)


def merged_input(recordings: list[Path], out: Path, registration: str = "shared", run_folder: bool = True) -> Path:
    """What `robocal run` / `calibrate` read: the one recording given, or the merge of several, written to
    ``OUT/import/merged.mcap`` (a run folder robocal owns) or ``OUT/merged.mcap`` (`calibrate`'s output
    folder); re-merged each time, bit-identical for the same sources, so later stages stay cached."""
    if len(recordings) == 1:
        if registration != "shared":
            raise RobocalError("--registration per-recording needs several recordings")
        return recordings[0]
    for p in recordings:
        if not Path(p).is_file():
            raise RobocalError(f"{p}: no such file")
    if not run_folder:
        Path(out).mkdir(parents=True, exist_ok=True)
        dst = Path(out) / "merged.mcap"
        from pipeline.recording.output import library_of

        if library_of(dst).endswith(f" {MERGED}"):  # calibrate's own merge of the last call: derived, re-merged
            dst.unlink()
        merge(recordings, dst, registration)
        return dst
    from pipeline.stages.runfolder import claim, fresh_stage_dir, locked

    with locked(out):
        claim(out)
        d = fresh_stage_dir(out, "import")
        dst = d / "merged.mcap"
        merge(recordings, dst, registration)
    return dst
