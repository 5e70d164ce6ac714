"""Stage validate: run the named checks of `pipeline.validate.checks` on a recording and its
ingested tables; write `validate/validate.json`.  Any fail makes the stage (and run) fail."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.ingest.streams import JOINT_STATE
from pipeline.ingest.temperature import TEMPERATURE
from pipeline.recording import joint_state_batch as JSB
from pipeline.recording.reader import read_recording
from pipeline.recording.schemas import CHANNELS, META_FIXTURE, META_ROBOT, validator
from pipeline.stages.artefacts import read_table, write_json
from pipeline.stages.ingest import NAME as INGEST, recording_info
from pipeline.validate import checks as C

NAME = "validate"


def _raw(rec, topic: str) -> list:
    raw = getattr(rec.messages, "raw", None)
    return raw[topic] if raw is not None else rec.messages[topic]


def _limits(rec, system) -> tuple[np.ndarray, np.ndarray, list[str]] | None:
    if hasattr(system, "joint_limits"):
        return system.joint_limits(rec)
    model = rec.metadata.get(META_ROBOT, {})
    if model.get("kind") == "delta":  # one actuator travel for the three legs
        from pipeline.models.delta import Delta

        try:
            d = Delta.from_dict(model)
        except (KeyError, ValueError, TypeError):
            return None
        return np.full(3, d.lower), np.full(3, d.upper), ["theta_11", "theta_12", "theta_13"]
    try:
        from pipeline.models.serial_arm import SerialArm

        arm = SerialArm.from_dict(rec.metadata[META_ROBOT])
        return arm.lower, arm.upper, [j.name for j in arm.joints]
    except Exception:  # noqa: BLE001 — a model that is not a serial arm has no limits here
        return None


def _stream_times(messages: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    ts, rec = [], []
    for i, m in enumerate(messages):
        t = m.get("timestamps_ns")
        if isinstance(t, list):
            try:
                a = np.asarray(t, np.int64)
            except (ValueError, TypeError, OverflowError):
                continue
            ts.append(a)
            rec.append(np.full(a.size, i))
    if not ts:
        return np.zeros(0, np.int64), np.zeros(0, int)
    return np.concatenate(ts), np.concatenate(rec)


def check_protobuf_stream(raw: list[bytes]) -> tuple[C.Check, tuple[np.ndarray, np.ndarray]]:
    """The protobuf encoder stream against `robocal.JointStateBatch`: every message that does not
    decode, has fields the schema lacks, inconsistent counts, other joint names or NaN/inf is
    named (fail); the sample times (ns) and message of each sample of the messages that do."""
    bad = JSB.bad_records(raw)
    check = C.make("schema", JOINT_STATE, [i for i, _ in bad], C.FAIL,
                   f"{JOINT_STATE}: {len(raw)} messages decode as {JSB.SCHEMA_NAME} (protobuf)",
                   f"do not match {JSB.SCHEMA_NAME} (first: record {bad[0][0]}: {bad[0][1]})" if bad else "")
    good = np.setdiff1d(np.arange(len(raw)), [i for i, _ in bad])
    if not good.size:
        return check, (np.zeros(0, np.int64), np.zeros(0, int))
    try:
        b = JSB.decode([raw[i] for i in good])
    except JSB.BatchError:  # only when no message names its joints: nothing to time
        return check, (np.zeros(0, np.int64), np.zeros(0, int))
    return check, (b.t_ns, good[b.message_index])


def run_checks(run_dir: Path, params: dict) -> list[C.Check]:
    from pipeline.systems.registry import SYSTEMS

    info = recording_info(run_dir)
    from pipeline.stages.ingest import SCENE

    rec = read_recording(info["source"]["path"], skip=SCENE)  # as ingest read it (one cached read)
    system = SYSTEMS[info["system"]]
    mchan = info["measurement_channel"]
    out: list[C.Check] = []
    topics = [t for t in sorted(rec.messages.raw if hasattr(rec.messages, "raw") else rec.messages) if _raw(rec, t)]
    decoded: dict[str, list[dict]] = {}
    for topic, why in getattr(rec, "registration", {}).items():
        if why:
            out.append(C.Check("registration", C.FAIL, f"{topic}: {why}", topic, []))
    stream_times = None
    for topic in topics:
        if topic == JOINT_STATE and getattr(rec, "encodings", {}).get(topic) == JSB.ENCODING:
            if not rec.registration.get(topic):  # else the registration check has failed
                check, stream_times = check_protobuf_stream(_raw(rec, topic))
                out.append(check)
            continue
        try:
            decoded[topic] = rec.messages[topic]
        except Exception as e:  # noqa: BLE001 — a message that is not JSON: fail naming it
            out.append(C.Check("decode", C.FAIL, str(e), topic, []))
    for topic, msgs in decoded.items():
        stem = CHANNELS.get(topic)
        out.append(C.check_schema(topic, msgs, validator(stem) if stem else None))
        out.append(C.check_finite(topic, msgs))
    # time
    span = None
    if JOINT_STATE in decoded or stream_times is not None:
        t, r = _stream_times(decoded[JOINT_STATE]) if stream_times is None else stream_times
        out += C.check_stream_time(JOINT_STATE, t, r, float(params.get("gap_factor", 5.0)))
        if t.size:
            span = (int(t.min()), int(t.max()))
    mpath = Path(run_dir) / INGEST / "measurements.parquet"
    table = read_table(mpath) if mpath.is_file() else None
    if mchan in decoded:
        msgs = decoded[mchan]
        if table is not None and "timestamp_ns" in table:
            t_m, rec_m = table["timestamp_ns"], table["record"]
            from pipeline.ingest.tables import times_in_order

            t_m, rec_m = times_in_order(table, rec_m)  # measured rows; in order within each merged recording
        else:
            ok = [(i, m["timestamp_ns"]) for i, m in enumerate(msgs) if isinstance(m.get("timestamp_ns"), int)]
            rec_m = np.array([i for i, _ in ok], int)
            t_m = np.array([t for _, t in ok], np.int64)
        for c in C.check_event_time(mchan, t_m, span):
            out.append(c if not c.records else C.Check(c.name, c.status, c.message, c.channel,
                                                       [int(rec_m[i]) for i in c.records]))
        t_msg = np.array([m["timestamp_ns"] if isinstance(m.get("timestamp_ns"), int) else -1 - i
                          for i, m in enumerate(msgs)], np.int64)
        out.append(C.check_duplicates(mchan, _raw(rec, mchan), t_msg))
    for topic in [*decoded, *([JOINT_STATE] if stream_times is not None else [])]:
        if topic != mchan:
            out.append(C.check_duplicates(topic, _raw(rec, topic)))
    if TEMPERATURE in decoded:
        t_meas = table["timestamp_ns"] if table is not None and "timestamp_ns" in table else None
        out += C.check_temperature(TEMPERATURE, decoded[TEMPERATURE], t_meas, mchan,
                                   table["record"] if t_meas is not None else None)
    # joint limits
    lim = _limits(rec, system)
    if lim is not None and table is not None and "joint_positions" in table:
        lo, hi, names = lim
        out.append(C.check_joint_limits(mchan, table["joint_positions"], table["record"], lo, hi, names))
        epath = Path(run_dir) / INGEST / "encoder.parquet"
        if epath.is_file():
            enc = read_table(epath)
            if all(f"q_{n}" in enc for n in names):
                q = np.stack([enc[f"q_{n}"] for n in names], axis=1)
                out.append(C.check_joint_limits(JOINT_STATE, q, enc["record"], lo, hi, names))
    # touch-jig faces
    fixture = rec.metadata.get(META_FIXTURE, {})
    if table is not None and fixture.get("kind") == "touch_jig" and {"face", "axis", "coordinate"} <= set(table):
        faces = {f["id"]: ("xyz".index(f["axis"]), float(f["coordinate"])) for f in fixture.get("faces", [])}
        out.append(C.check_face_coordinates(mchan, table["face"], table["axis"], table["coordinate"],
                                            table["record"], faces))
    # ingest could not build the tables for a reason no check named: fail with it
    if info.get("errors") and not any(c.status == C.FAIL for c in out):
        out.append(C.Check("ingest", C.FAIL, info["errors"][0], mchan, []))
    # gross outliers after a first robust fit (only on data that passed everything else)
    from pipeline.dynamics.stage import is_dynamics_run

    if is_dynamics_run(run_dir):  # efforts: the checks of a dynamics recording replace the geometric screen
        from pipeline.dynamics.checks import dynamics_checks

        return out + dynamics_checks(run_dir, table, mchan, out)
    if table is not None and not any(c.status == C.FAIL for c in out):
        from pipeline.ingest.tables import model_columns
        from pipeline.stages.ingest import load_system

        _, model, _ = load_system(run_dir)
        from pipeline.recording.schemas import META_CAMPAIGN
        from pipeline.validate.plausibility import screen

        # residuals orders of magnitude above the instrument: wrong units, columns or chain (listed when it fails)
        gross = screen(model, model_columns(table), rec.metadata.get(META_CAMPAIGN, {}))
        if gross["status"] == "fail":
            out.append(C.Check("plausibility", C.FAIL, f"{mchan}: {gross['message']}", mchan, []))
            return out
        from pipeline.validate.outlier_fit import DEFAULT_CAP, first_fit, still_falling

        cap = int(params.get("outlier_fit_max_nfev", DEFAULT_CAP))
        # a model whose residuals are not metres (a camera's px) states its own robust scale
        scale = getattr(model, "robust_scale", None) or float(params.get("outlier_f_scale_m", 1e-4))
        f = first_fit(model, model_columns(table), scale, cap)
        out.append(C.check_outliers(mchan, f.residuals_after, table["record"], float(params.get("outlier_threshold", 6.0))))
        if not f.converged and still_falling(f.history):  # the screen stands on an iterate short of the minimum
            out.append(C.Check("outlier_fit", C.WARN, f"{mchan}: the first robust fit stopped at its {cap}-"
                               "evaluation cap before converging; outliers were screened on its last iterate",
                               mchan, []))
    return out


def name_the_file(checks: list[C.Check], path: str) -> list[C.Check]:
    """Every warn/fail message starts with the recording's path (file, channel, records)."""
    return [c if c.status == C.PASS or c.message.startswith(str(path)) else
            C.Check(c.name, c.status, f"{path}: {c.message}", c.channel, c.records) for c in checks]


def summarise(checks: list[C.Check]) -> dict:
    status = C.FAIL if any(c.status == C.FAIL for c in checks) else (
        C.WARN if any(c.status == C.WARN for c in checks) else C.PASS)
    fails = [c for c in checks if c.status == C.FAIL]
    doc = {"status": status, "checks": [c.to_dict() for c in checks],
           "counts": {s: sum(c.status == s for c in checks) for s in (C.PASS, C.WARN, C.FAIL)}}
    if fails:
        doc["reason"] = f"validation check {fails[0].name} failed: {fails[0].message}"
    return doc


def run(run_dir: Path, params: dict) -> dict:
    checks = name_the_file(run_checks(Path(run_dir), params), recording_info(Path(run_dir))["source"]["path"])
    doc = summarise(checks)
    write_json(Path(run_dir) / NAME / "validate.json", {"checks": doc["checks"], "status": doc["status"]})
    return doc
