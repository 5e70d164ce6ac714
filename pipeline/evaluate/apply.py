"""Apply a calibrated model to other recordings without refitting it (`robocal evaluate`).

Every parameter the calibration estimated — robot geometry, instrument registration, tool and
target offsets, unknown planes of the same name — is carried over as fitted.  What a recording
has of its own and the calibration cannot know is estimated from that recording alone with the
robot held: the sockets of a coincidence recording (each group's mean ball centre, see
`errors.coincidence_errors`) and planes the calibration never saw.  With ``refit="registration"``
the instrument frame (``base.*``) is re-estimated too, once over all recordings (``shared``, one
instrument that moved) or per recording.

A recording is refused (one line, `RobocalError`) when it is of another robot or chain (robot name,
root, tip, joint names, campaign ``robot_id``), of another measurement type, or measured with
another instrument than the registration it would share (campaign ``instrument`` or the ROS 2
import's ``frame_id``, when both sides name one).  Camera images are evaluated with the calibration's
camera (intrinsics, lens model and distortion terms, hand-eye, board): a recording of another image size,
mount or lens is refused; nothing of the camera is estimated from the evaluated images (the base frame
only with ``refit="registration"``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from pipeline.errors import RobocalError
from pipeline.evaluate.calibrated import Calibrated
from pipeline.evaluate import postures
from pipeline.evaluate.errors import RowErrors, by_label, row_errors, summarise
from pipeline.recording.schemas import META_CAMPAIGN, META_URDF

REFITS = ("none", "registration")
REGISTRATIONS = ("shared", "per-recording")


def instrument_of(campaign: dict) -> str | None:
    """The instrument a recording was measured with, when its campaign names one."""
    name = campaign.get("instrument") or (campaign.get("ros2") or {}).get("frame_id")
    return str(name) if name else None


def check_compatible(cal: Calibrated, rec) -> None:
    """Refuse a recording of another robot, chain or measurement type than `cal`'s (one line)."""
    from pipeline.models import urdf

    meta, camp = rec.metadata.get(META_URDF) or {}, rec.metadata.get(META_CAMPAIGN) or {}
    if camp.get("system") != "urdf" or not isinstance(meta, dict) or "urdf" not in meta:
        raise RobocalError(f"{rec.path}: not a URDF-robot recording (system {camp.get('system')!r}); "
                           f"{cal.run_dir} calibrated a URDF robot")
    for k in ("root", "tip", "tips"):
        if meta.get(k) != cal.urdf.get(k):
            raise RobocalError(f"{rec.path}: chain {k} {meta.get(k)!r}, but {cal.run_dir} calibrated the chain "
                               f"{cal.urdf.get('root')!r} → {cal.urdf.get('tips') or cal.urdf.get('tip')!r}")
    if (camp.get("coupled") or {}) != (cal.campaign.get("coupled") or {}):
        raise RobocalError(f"{rec.path}: coupled joints {camp.get('coupled') or {}}, but {cal.run_dir} was calibrated "
                           f"with {cal.campaign.get('coupled') or {}}")
    mine = urdf.parse(meta["urdf"], meta["root"], meta["tip"], source=f"{rec.path}: metadata robocal.urdf",
                      allow_mimic=True)
    theirs = urdf.parse(cal.urdf["urdf"], cal.urdf["root"], cal.urdf["tip"], source=f"{cal.run_dir}", allow_mimic=True)
    if mine.name != theirs.name or mine.joint_names != theirs.joint_names:
        raise RobocalError(f"{rec.path}: robot {mine.name!r} with joints {mine.joint_names}, but {cal.run_dir} "
                           f"calibrated robot {theirs.name!r} with joints {theirs.joint_names}")
    a, b = camp.get("robot_id"), cal.campaign.get("robot_id")
    if a and b and a != b:
        raise RobocalError(f"{rec.path}: robot_id {a!r}, but {cal.run_dir} calibrated robot_id {b!r}")
    if camp.get("measure") != cal.campaign.get("measure"):
        raise RobocalError(f"{rec.path}: {camp.get('measure')} measurements, but {cal.run_dir} was calibrated with "
                           f"{cal.campaign.get('measure')} measurements")
    if camp.get("measure") == "camera":
        for k in ("image_size", "mount", "lens", "target"):
            if camp.get(k) != cal.campaign.get(k):
                raise RobocalError(f"{rec.path}: camera {k} {camp.get(k)!r}, but {cal.run_dir} calibrated "
                                   f"{cal.campaign.get(k)!r} (another camera, mount or board)")


def check_instruments(cal: Calibrated, recs: list, refit: str, registration: str) -> None:
    """Recordings that would share a registration must come from one instrument."""
    if refit == "registration" and registration == "per-recording":
        return
    ref = None if refit == "registration" else (instrument_of(cal.campaign), str(cal.run_dir))
    for rec in recs:
        mine = instrument_of(rec.metadata.get(META_CAMPAIGN) or {})
        if mine is None:
            continue
        if ref is not None and ref[0] is not None and mine != ref[0]:
            what = "the calibration" if refit == "none" else "another recording"
            raise RobocalError(f"{rec.path}: instrument {mine!r}, but {what} ({ref[1]}) used {ref[0]!r}: a shared "
                               "registration cannot serve both (--refit registration --registration per-recording)")
        if ref is None or ref[0] is None:
            ref = (mine, str(rec.path))


def transfer(cal: Calibrated, model, path) -> tuple[np.ndarray, list[str]]:
    """`model`'s parameter vector with every value `cal` estimated; and the names `cal` has no value
    for (the recording's own: new planes; sockets are not parameters of the evaluation)."""
    values = cal.values()
    x = model.nominal()
    own = []
    for i, n in enumerate(model.parameter_names()):
        if n in values:
            x[i] = values[n]
        elif n.startswith("target"):
            raise RobocalError(f"{path}: measures target {n.split('.')[0]}, which {cal.run_dir} did not calibrate")
        elif not n.startswith("point."):
            own.append(n)
    return x, own


def _refit(model, data, x: np.ndarray, free: list[str]) -> np.ndarray:
    from pipeline.identify.least_squares import FitOptions, fit

    if not free:
        return x
    fixed = tuple(n for n in model.parameter_names() if n not in set(free))
    return fit(model, data, FitOptions(fixed=fixed, x0=x, before=False)).x


def _concat(tables: list[dict]) -> dict:
    return {k: np.concatenate([np.asarray(t[k]) for t in tables]) for k in tables[0]}


def evaluate(cal: Calibrated, recs: list, refit: str = "none", registration: str = "shared") -> list[dict]:
    """Per recording: {path, measure, figures…, groups, row errors (`RowErrors`, key ``rows``), record}."""
    from pipeline.models.urdf_arm import UrdfArm
    from pipeline.models import urdf
    from pipeline.systems import urdf_robot

    if refit not in REFITS or registration not in REGISTRATIONS:
        raise RobocalError(f"--refit {refit!r} / --registration {registration!r}: expected one of "
                           f"{', '.join(REFITS)} / {', '.join(REGISTRATIONS)}")
    for rec in recs:
        check_compatible(cal, rec)
    check_instruments(cal, recs, refit, registration)
    arm = UrdfArm(urdf.parse(cal.urdf["urdf"], cal.urdf["root"], cal.urdf["tip"], source=str(cal.run_dir)))
    measure = cal.campaign.get("measure")
    items = []
    for rec in recs:
        model_rec, table = urdf_robot.load(rec)
        tree = urdf_robot.model_like(rec, cal.names) if measure == "point" else None
        if tree is not None:  # several tips, coupled joints or physics terms: the calibration's own structure
            model = replace(tree, kin=replace(tree.kin, descs=tuple(replace(d, urdf=cal.urdf["urdf"]) for d in
                                                                    tree.kin.descs)))
        elif measure == "camera":  # the calibration's camera: its distortion terms, whatever this import declared
            model = replace(model_rec, kin=arm, n_dist=int(cal.campaign.get("n_dist", model_rec.n_dist)))
        else:
            model = replace(model_rec, kin=arm)
        x, own = transfer(cal, model, rec.path)
        if measure == "camera" and own:
            raise RobocalError(f"{rec.path}: {cal.run_dir} has no value for {', '.join(own[:4])}: not a calibration "
                               "of this camera")
        items.append([rec, model, table, x, own])
    reg = [n for n in items[0][1].parameter_names() if n.startswith("base.")] if refit == "registration" else []
    if measure == "coincidence":
        reg = []  # ball-centre spreads and socket distances do not depend on the instrument frame
    if reg and registration == "shared" and len(items) > 1:
        names = [it[1].parameter_names() for it in items]
        if any(n != names[0] for n in names):
            raise RobocalError("the recordings have different own parameters (planes): a shared registration needs "
                               "one model; use --registration per-recording")
        xs = _refit(items[0][1], _concat([it[2] for it in items]), items[0][3],
                    reg + sorted({n for it in items for n in it[4]}))
        for it in items:
            it[3] = xs
    else:
        for it in items:
            it[3] = _refit(it[1], it[2], it[3], reg + it[4])
    out = []
    for rec, model, table, x, own in items:
        errs = row_errors(model, x, table, measure)
        doc = {"path": str(rec.path), "measure": measure, **summarise(errs, measure),
               "registration": ("as calibrated" if not reg else f"refitted ({registration})")}
        if measure == "camera":
            doc |= {"residual_unit": "px", "images": int(len(np.unique(np.asarray(table["image"]))))}
        post = posture_labels(cal, table, errs, measure)
        if post is not None:
            doc["postures"] = by_label(errs, post, postures.GROUPS, measure)
        if reg:
            doc["registration_values"] = {n: float(x[model.parameter_names().index(n)]) for n in reg}
        if own:
            doc["own_parameters_fitted"] = own
        out.append(doc | {"rows": errs, "record": np.asarray(table["record"], np.int64), "posture": post})
    return out


def posture_labels(cal: Calibrated, table: dict, errs: RowErrors, measure: str) -> np.ndarray | None:
    """Each row's posture group relative to the calibration's training postures (`postures.GROUPS`; distance
    rows ""), for point and pose data whose calibration knows its postures; else None."""
    q = np.asarray(table["joint_positions"], float)
    if measure not in ("point", "pose") or cal.q_train is None or q.ndim != 2 or cal.q_train.shape[1:] != q.shape[1:]:
        return None
    out = np.full(len(q), "", object)
    m = errs.kind == 0
    out[m] = postures.labels(cal.q_train, q[m])
    return out


def error_table(results: list[dict]) -> dict[str, np.ndarray]:
    """One row per measurement of every recording: recording, record, label, kind, posture (its group relative
    to the training postures, `postures.GROUPS`, or ""), e_0…, norm_m."""
    cols: dict[str, list] = {"recording": [], "record": [], "label": [], "kind": [], "posture": [], "norm_m": []}
    k = max(r["rows"].error.shape[1] for r in results)
    for j in range(k):
        cols[f"e_{j}"] = []
    for r in results:
        e: RowErrors = r["rows"]
        n = len(e.norm)
        cols["recording"].append(np.full(n, r["path"], object))
        cols["record"].append(r["record"])
        cols["label"].append(e.label.astype(str).astype(object))
        cols["kind"].append(e.kind.astype(np.int64))
        cols["posture"].append(r["posture"] if r.get("posture") is not None else np.full(n, "", object))
        cols["norm_m"].append(e.norm)
        for j in range(k):
            cols[f"e_{j}"].append(e.error[:, j] if j < e.error.shape[1] else np.full(n, np.nan))
    return {c: np.concatenate(v) for c, v in cols.items()}
