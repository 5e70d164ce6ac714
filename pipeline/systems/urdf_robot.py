"""Any URDF robot with any of the generic measurement types (`pipeline.measurements`).

A recording of this system carries the URDF and the chain choice in the metadata record
``robocal.urdf`` ({urdf, root, tip, source}), the campaign (``robocal.campaign``: system
"urdf", ``measure`` point|pose|plane|coincidence|camera, ``joint_names``, and per type ``planes``,
``distances``, ``sigma_m``/``sigma_rad``, ``n_targets``; camera: `pipeline.camera.table`) and one
message per measurement (camera: per image) on ``/measure/<type>`` (`schemas/measure_*.schema.json`).
An encoder stream is optional.
"""

from __future__ import annotations

import numpy as np

from pipeline.errors import RobocalError, where
from pipeline.measurements.coincidence import CoincidenceModel
from pipeline.measurements.plane import Plane, PlaneModel
from pipeline.measurements.point import PointModel
from pipeline.measurements.pose import PoseModel
from pipeline.models import urdf
from pipeline.models.urdf_arm import UrdfArm
from pipeline.recording.schemas import META_CAMPAIGN, META_URDF

SYSTEM = "urdf"
MEASURES = ("point", "pose", "plane", "coincidence", "camera", "effort")
MEASUREMENT_CHANNEL = "/measure/point"
STREAM_OPTIONAL = True
GROUP_COLUMN = "label"


def channel_of(measure: str) -> str:
    """The measurement channel of a measurement type (effort: the encoder stream's samples themselves)."""
    return "/robot/joint_state" if measure == "effort" else f"/measure/{measure}"


def channel_for(rec) -> str:
    """The measurement channel of this recording (by its campaign's measurement type)."""
    try:
        return channel_of(campaign_measure(rec))
    except RobocalError:
        return MEASUREMENT_CHANNEL


def campaign_measure(rec) -> str:
    m = rec.meta(META_CAMPAIGN).get("measure")
    if m not in MEASURES:
        raise RobocalError(f"{rec.path}: metadata robocal.campaign: measure {m!r} is not one of {', '.join(MEASURES)}")
    return m


def arm_of(rec) -> UrdfArm:
    meta = rec.meta(META_URDF)
    if not isinstance(meta, dict) or not all(isinstance(meta.get(k), str) for k in ("urdf", "root", "tip")):
        raise RobocalError(f"{rec.path}: metadata robocal.urdf must hold strings urdf, root and tip")
    desc = urdf.parse(meta["urdf"], meta["root"], meta["tip"], source=f"{rec.path}: metadata robocal.urdf")
    names = rec.meta(META_CAMPAIGN).get("joint_names", desc.joint_names)
    if list(names) != desc.joint_names:
        raise RobocalError(f"{rec.path}: campaign joint_names {names} differ from the chain's {desc.joint_names}")
    return UrdfArm(desc)


def is_tree(rec) -> bool:
    """Whether the recording needs the tree model: several tips or coupled joints."""
    meta, campaign = rec.meta(META_URDF), rec.meta(META_CAMPAIGN)
    tips = meta.get("tips") if isinstance(meta, dict) else None
    return bool((isinstance(tips, list) and len(tips) > 1) or campaign.get("coupled"))


def tree_of(rec, lateral: tuple[str, ...] = ()):
    """The recording's `UrdfTree`: chains root → each of robocal.urdf's `tips` (or its `tip`),
    joints coupled by the campaign's `coupled` ({joint: {terms: {joint: factor}, offset: rad}}) or by
    the URDF's `<mimic>` elements."""
    from pipeline.models.coupling import check_coupling
    from pipeline.models.urdf_tree import UrdfTree

    meta, campaign = rec.meta(META_URDF), rec.meta(META_CAMPAIGN)
    if not isinstance(meta, dict) or not all(isinstance(meta.get(k), str) for k in ("urdf", "root", "tip")):
        raise RobocalError(f"{rec.path}: metadata robocal.urdf must hold strings urdf, root and tip")
    src = f"{rec.path}: metadata robocal.urdf"
    tips = meta.get("tips") or [meta["tip"]]
    if not isinstance(tips, list) or not all(isinstance(t, str) for t in tips) or len(set(tips)) != len(tips):
        raise RobocalError(f"{src}: tips must be a list of distinct link names")
    descs = tuple(urdf.parse(meta["urdf"], meta["root"], t, source=src, allow_mimic=True) for t in tips)
    movable = {j.name for d in descs for j in d.movable}
    coupled = {c: v for c, v in urdf.mimic_couplings(meta["urdf"], src).items() if c in movable}
    for c, v in (campaign.get("coupled") or {}).items():
        terms = v.get("terms") if isinstance(v, dict) else None
        if c not in movable or not isinstance(terms, dict) or not terms:
            raise RobocalError(f"{rec.path}: metadata robocal.campaign: coupled joint {c!r} is not a movable joint "
                               "of the chains or has no terms")
        try:
            coupled[c] = ({str(k): float(f) for k, f in terms.items()}, float(v.get("offset", 0.0)))
        except (TypeError, ValueError):
            raise RobocalError(f"{rec.path}: metadata robocal.campaign: coupled joint {c!r}: factors and offset must "
                               "be numbers") from None
    check_coupling(coupled, movable, f"{rec.path}: metadata robocal.campaign",
                   {j.name: j.type for d in descs for j in d.movable})
    tree = UrdfTree(descs, coupled=tuple((c, tuple(sorted(t.items())), o) for c, (t, o) in sorted(coupled.items())),
                    lateral=tuple(lateral))
    names = campaign.get("joint_names", tree.joint_names)
    if list(names) != tree.joint_names:
        raise RobocalError(f"{rec.path}: campaign joint_names {names} differ from the tree's read joints "
                           f"{tree.joint_names}")
    return tree


def physics_model(rec, table: dict, physics: str | None = None, payload: tuple = ()):
    """A `TreePointModel` of a point recording, with the physics terms `physics` asks for
    (`pipeline.physics.compliance.parse_spec`); None where the rigid single-chain model serves.
    ``auto`` offers the reading-error terms (`pipeline.physics.encoder`) only to a model that carries
    physics terms anyway (a tree, a URDF with masses): a rigid single chain stays rigid."""
    from pipeline.measurements.tree_point import TreePointModel
    from pipeline.physics import compliance, encoder

    mode, families = compliance.parse_spec(physics or "none")
    tree = is_tree(rec)
    meta = rec.meta(META_URDF)
    gravity = tuple(f for f in families if f in compliance.GRAVITY)
    if mode == "auto":
        from pipeline.physics.gravity import has_inertials

        if not (isinstance(meta, dict) and isinstance(meta.get("urdf"), str) and has_inertials(meta["urdf"])):
            gravity = ()
    if payload and not gravity:
        raise RobocalError(f"{rec.path}: --payload needs gravity terms (--physics auto or a list, and URDF inertials)")
    if not tree and not gravity and (mode == "auto" or not families):
        return None
    rigid = tree_of(rec)
    compliant, lateral = compliance.candidates(rigid, table["joint_positions"], gravity, payload,
                                               source=f"{rec.path}: metadata robocal.urdf")
    reading = encoder.candidates(rigid, table["joint_positions"], tuple(f for f in families if f in encoder.FAMILIES),
                                 table.get("approach"))
    carried = any(n.endswith(".backlash") for n in reading)
    stiffening = compliant if "load-compliance" in gravity else ()
    compliant = compliant if "joint-compliance" in gravity else ()
    return TreePointModel(tree_of(rec, lateral), compliant=compliant, payload=payload, forced=mode == "fixed",
                          stiffening=stiffening,
                          encoder=reading, absent=("backlash",) if "backlash" in families and not carried else ())


def model_like(rec, names: list[str], payload: tuple = ()):
    """The `TreePointModel` of a point recording with the physics terms a calibration has (`names`: its
    parameter names — ``J.compliance``, ``J.lateral1``, ``J.ecc_sin`` …), whatever this recording's loads:
    a calibrated model is applied as it was fitted.  None when `names` hold no physics term and `rec` is
    no tree."""
    from pipeline.measurements.tree_point import TreePointModel
    from pipeline.physics.encoder import is_encoder

    compliant = tuple(n.rsplit(".", 1)[0] for n in names if n.endswith(".compliance"))
    stiffening = tuple(n.rsplit(".", 1)[0] for n in names if n.endswith(".compliance_load"))
    lateral = tuple(n.rsplit(".", 1)[0] for n in names if n.endswith(".lateral1"))
    reading = tuple(n for n in names if is_encoder(n))
    if not (compliant or stiffening or lateral or reading or is_tree(rec)):
        return None
    tree = tree_of(rec, lateral)
    known = {j.name for j in tree.all_joints}
    used = set(compliant + stiffening + lateral + tuple(n.rsplit(".", 1)[0] for n in reading))
    if not used <= known:
        raise RobocalError(f"{rec.path}: the calibration's physics terms name joints {sorted(used - known)} "
                           "that are not in this recording's chains")
    return TreePointModel(tree, compliant=compliant, payload=payload, encoder=reading, stiffening=stiffening)


def model_for(arm: UrdfArm, measure: str, campaign: dict, labels: list[str] | None = None):
    """The measurement model of `measure` over `arm` (campaign settings applied)."""
    if measure == "point":
        return PointModel(arm, n_targets=int(campaign.get("n_targets", 1)))
    if measure == "pose":
        return PoseModel(arm, sigma_m=float(campaign.get("sigma_m", 1e-3)),
                         sigma_rad=float(campaign.get("sigma_rad", 1e-3)))
    if measure == "camera":
        from pipeline.camera.table import camera_model

        return camera_model(arm, campaign)
    if measure == "plane":
        planes = tuple(Plane(str(p["name"]), tuple(float(v) for v in p.get("normal", (0, 0, 1))),
                             float(p.get("offset", 0.0)), bool(p.get("known", True)))
                       for p in campaign.get("planes", []))
        return PlaneModel(arm, planes=planes, fit_tool=tool_setting(campaign))
    groups = tuple(labels or [str(g) for g in campaign.get("groups", [])])
    return CoincidenceModel(arm, groups_=groups, fit_tool=tool_setting(campaign))


def tool_setting(campaign: dict) -> bool | None:
    """The campaign's ``fit_tool`` (True: the tool point estimated, False: held known), None where it says
    nothing (held known unless the left-out groups of the model choice free it)."""
    v = campaign.get("fit_tool")
    return None if v is None else bool(v)


def _column(rec, topic, msgs, key, shape, dtype=float):
    out = []
    for i, m in enumerate(msgs):
        if key not in m:
            raise RobocalError(f"{where(rec.path, topic, i)}: field {key!r} missing")
        try:
            v = np.asarray(m[key], dtype=dtype)
        except (TypeError, ValueError, OverflowError):
            raise RobocalError(f"{where(rec.path, topic, i)}: field {key!r} is not numeric") from None
        if v.shape != shape:
            raise RobocalError(f"{where(rec.path, topic, i)}: field {key!r} has shape {v.shape}, expected {shape}")
        if dtype is float and not np.all(np.isfinite(v)):
            raise RobocalError(f"{where(rec.path, topic, i)}: field {key!r} has NaN or inf")
        out.append(v)
    return np.stack(out) if out else np.zeros((0,) + shape, dtype)


def _approach(rec, topic, msgs, nj: int) -> np.ndarray:
    """(n, n_joints) int8 direction of approach per joint (−1/0/+1; 0 where a message has none)."""
    out = np.zeros((len(msgs), nj), np.int8)
    for i, m in enumerate(msgs):
        if "approach" not in m:
            continue
        v = np.asarray(m["approach"], float)
        if v.shape != (nj,) or not np.all(np.isin(v, (-1.0, 0.0, 1.0))):
            raise RobocalError(f"{where(rec.path, topic, i)}: field 'approach' must hold {nj} values of -1, 0 or +1")
        out[i] = v.astype(np.int8)
    return out


def approach_from_stream(rec, t_ns: np.ndarray, joints: list[str]) -> np.ndarray | None:
    """(n, n_joints) int8 direction of approach of each joint at the measurement times `t_ns` (ns) from
    the recording's encoder stream (`/robot/joint_state`): the sign of the joint's last motion before
    the measurement (`pipeline.ingest.context.last_motion_sign`; 0 where it did not move within the
    look-back or is not in the stream).  None without a readable stream, or where no joint moved before
    any measurement (the recording then carries no direction)."""
    from pipeline.ingest.context import last_motion_sign
    from pipeline.ingest.streams import JOINT_STATE, joint_stream

    if not rec.messages.raw.get(JOINT_STATE) or not len(t_ns):
        return None
    try:
        s = joint_stream(rec)
    except RobocalError:  # a damaged stream is validate's finding; the measurements stand without directions
        return None
    cols = [s.names.index(j) if j in s.names else -1 for j in joints]
    if len(s) < 2 or all(c < 0 for c in cols):
        return None
    sign = last_motion_sign(s.t_ns, s.q[:, [max(c, 0) for c in cols]], np.asarray(t_ns, np.int64))
    d = np.where(np.array(cols) >= 0, sign, 0).astype(np.int8)
    return d if d.any() else None


def load(rec, physics: str | None = None, payload: tuple = ()):
    """Measurement model and measurement table of a URDF recording.  `physics` and `payload`: the
    gravity terms offered to identification (`physics_model`; point measurements); None keeps the
    rigid model (the command line and the run's stages ask for ``auto`` by default)."""
    measure = campaign_measure(rec)
    if measure == "effort":  # dynamics: the stream's samples (pipeline.systems.urdf_dynamics)
        from pipeline.systems import urdf_dynamics

        if payload or physics not in (None, "auto", "none"):
            raise RobocalError(f"{rec.path}: --physics / --payload are gravity terms of point measurements; a "
                               "dynamics recording identifies its inertial parameters")
        return urdf_dynamics.load(rec)
    campaign = rec.meta(META_CAMPAIGN)
    if is_tree(rec) and measure != "point":
        raise RobocalError(f"{rec.path}: several tips or coupled joints need point measurements (got {measure})")
    arm = tree_of(rec) if is_tree(rec) else arm_of(rec)
    topic = channel_of(measure)
    msgs = rec.require(topic)
    if measure == "camera":
        from pipeline.camera.table import camera_table

        return model_for(arm, measure, campaign), camera_table(rec, topic, msgs, arm, campaign)
    n = len(msgs)
    table = {"timestamp_ns": _column(rec, topic, msgs, "timestamp_ns", (), np.int64),
             "joint_positions": _column(rec, topic, msgs, "joint_positions", (arm.n_joints,)),
             "record": np.arange(n)}
    labels = None
    if measure in ("point", "pose"):
        table["position"] = _column(rec, topic, msgs, "position", (3,))
    if measure == "point":
        table["target"] = np.array([int(m.get("target", 0)) for m in msgs], np.int64)
        if any("approach" in m for m in msgs):  # explicit directions win over the stream's
            table["approach"] = _approach(rec, topic, msgs, arm.n_joints)
        elif (derived := approach_from_stream(rec, table["timestamp_ns"], arm.joint_names)) is not None:
            table["approach"] = derived
        table["label"] = np.array([f"target {t}" for t in table["target"]], object)
    if measure == "pose":
        quat = _column(rec, topic, msgs, "orientation", (4,))
        norm = np.linalg.norm(quat, axis=1)
        bad = np.flatnonzero(np.abs(norm - 1) > 1e-3)
        if bad.size:
            raise RobocalError(f"{where(rec.path, topic, int(bad[0]))}: orientation is not a unit quaternion "
                               f"(norm {norm[bad[0]]:.4g})")
        table["orientation"] = quat / norm[:, None]
        table["label"] = np.full(n, "pose", object)
    if measure in ("plane", "coincidence"):
        key = "plane" if measure == "plane" else "group"
        names = [str(m.get(key, "")) for m in msgs]
        if measure == "plane":
            labels = [str(p["name"]) for p in campaign.get("planes", [])]
        else:
            labels = list(dict.fromkeys(names))
        index = {g: i for i, g in enumerate(labels)}
        for i, g in enumerate(names):
            if g not in index:
                raise RobocalError(f"{where(rec.path, topic, i)}: {key} {g!r} is not declared in the campaign "
                                   f"(known: {', '.join(labels)})")
        table[key] = np.array([index[g] for g in names], np.int64)
        table["label"] = np.array(names, object)
    if measure == "coincidence":
        table["group"] = table.pop("group")
    if measure != "point" and (payload or physics not in (None, "auto", "none")):
        raise RobocalError(f"{rec.path}: --physics {physics} / --payload need point measurements (got {measure})")
    model = physics_model(rec, table, physics, payload) if measure == "point" else None
    if model is None:
        model = model_for(arm, measure, campaign, labels)
    sessions = campaign.get("sessions") or []
    if sessions:  # several recordings calibrated together (pipeline.importers.merge)
        counts = [int(s.get("rows", 0)) for s in sessions]
        if sum(counts) != n:
            raise RobocalError(f"{rec.path}: metadata robocal.campaign: sessions hold {sum(counts)} rows, "
                               f"{topic} has {n}")
        table["session"] = np.repeat(np.arange(len(counts)), counts).astype(np.int64)
        if campaign.get("registration") == "per-recording" and len(counts) > 1 and measure != "coincidence":
            from pipeline.measurements.sessions import SessionFrames

            model = SessionFrames(model, len(counts))
    if measure == "coincidence" and campaign.get("distances"):
        table = _with_distances(rec, table, campaign["distances"], labels, arm.n_joints)
    return model, table


def _with_distances(rec, table: dict, distances: list, labels: list[str], nj: int) -> dict:
    """Append one row per known distance between two groups' points (kind = 1)."""
    index = {g: i for i, g in enumerate(labels)}
    rows = []
    for d in distances:
        a, b = str(d.get("a")), str(d.get("b"))
        if a not in index or b not in index:
            raise RobocalError(f"{rec.path}: metadata robocal.campaign: distance between unknown groups {a!r}, {b!r}")
        rows.append((index[a], index[b], float(d["distance"])))
    n, k = len(table["record"]), len(rows)
    out = {c: np.concatenate([v, np.zeros((k,) + v.shape[1:], v.dtype)]) for c, v in table.items() if c != "label"}
    out["label"] = np.concatenate([table["label"], np.array(["distance"] * k, object)])
    out["kind"] = np.r_[np.zeros(n, np.int64), np.ones(k, np.int64)]
    out["group"][n:] = [r[0] for r in rows]
    out["group_b"] = np.r_[np.zeros(n, np.int64), [r[1] for r in rows]].astype(np.int64)
    out["distance"] = np.r_[np.zeros(n), [r[2] for r in rows]]
    out["record"] = np.arange(n + k)
    return out


def joint_limits(rec):
    """(lower, upper, names) of the chain's movable joints for validate, widened as the importer
    does (`importers.bounds.LIMIT_SLACK` of each range): real robots read a little past their URDF's
    nominal limits; far past them is a unit mistake and fails."""
    from pipeline.importers.bounds import LIMIT_SLACK

    arm = tree_of(rec) if is_tree(rec) else arm_of(rec)
    lo, hi = arm.lower, arm.upper
    span = np.where(np.isfinite(hi - lo), hi - lo, 0.0)
    return lo - LIMIT_SLACK * span, hi + LIMIT_SLACK * span, arm.joint_names
