"""Thermal drift driven by a recorded temperature channel.

A warm-up ΔT(t) = ΔT∞·(1 − exp(−t/τ)) moves the true tip by g·ΔT; with the `/arm/temperature`
sensor logged the diagnosis models the drift against the temperature, without it only against
time.  One IK'd target set per module; each case re-runs only the contact searches.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from mcap.reader import make_reader

from pipeline.diagnose import Settings, diagnose
from pipeline.diagnose.stage import diagnose_recording
from pipeline.errors import RobocalError
from pipeline.ingest.temperature import TEMPERATURE, rise_at, temperature_stream
from pipeline.models.jig import stepped_block
from pipeline.recording.reader import read_recording
from pipeline.recording.schemas import CHANNELS, META_CAMPAIGN, schema_bytes, validator
from pipeline.recording.writer import RecordingWriter
from pipeline.simulate import effects as se
from pipeline.simulate import thermal
from pipeline.simulate.arc_welder import Campaign, Noise
from pipeline.systems import arc_welder as aw
from pipeline.validate.checks import FAIL, check_temperature

NOM, TRUE, JIG = aw.nominal_arm(), aw.reference_truth(), stepped_block()
CAMPAIGN = replace(Campaign(contacts=100, seed=3), dwell_s=10.0)  # ≈ 50 min: a warm-up
WARM = (900.0, 8.0)  # τ = 15 min, ΔT∞ = 8 K
G = (4e-5, 0.0, 3e-5)  # m/K of tip drift in {W}


def variations(sensor: bool, warm: tuple = WARM) -> se.Variations:
    return se.Variations(payloads_kg=(0.0, 6.0), search_speeds_m_s=(0.005, 0.01, 0.02), warm_up=warm,
                         temperature_sensor=sensor)


@pytest.fixture(scope="module")
def targets():
    return se.plan_targets(NOM, JIG, CAMPAIGN, truth=TRUE)


def run(targets, effects=(), sensor=True, warm=WARM, seed=0, n_boot=40):
    es = se.run(NOM, TRUE, JIG, targets, CAMPAIGN, Noise(), [se.parse_effect(e) for e in effects],
                variations(sensor, warm), seed=seed)
    return diagnose(aw.TouchModel(NOM), se.diagnosis_table(es, JIG), jig_tolerance_m=JIG.tolerance_m,
                    settings=Settings(n_boot=n_boot))


def drift(g=G) -> str:
    return "thermal_drift=" + ",".join(f"{v:g}" for v in g)


def test_temperature_recording_round_trips_byte_for_byte(tmp_path):
    r = thermal.read_sensor(thermal.WarmUp(*WARM), 0, 120_000_000_000, np.random.default_rng(0))
    first, again = tmp_path / "t.mcap", tmp_path / "again.mcap"
    with RecordingWriter(first) as w:
        w.metadata(META_CAMPAIGN, {"system": "arc-welder"})
        for topic, m in r.messages():
            w.write(topic, m)
    with open(first, "rb") as f:
        summary = make_reader(f).get_summary()
        (ch,) = summary.channels.values()
        assert ch.topic == TEMPERATURE and summary.schemas[ch.schema_id].data == schema_bytes(CHANNELS[TEMPERATURE])
    rec = read_recording(first)
    for m in rec.messages[TEMPERATURE]:
        validator("temperature").validate(m)
    with RecordingWriter(again) as w:
        w.metadata(META_CAMPAIGN, rec.metadata[META_CAMPAIGN])
        for m in rec.messages[TEMPERATURE]:
            w.write(TEMPERATURE, m)
    assert again.read_bytes() == first.read_bytes()
    ts = temperature_stream(rec)
    assert ts.sensor == "link2" and ts.t_ns.size == 121
    assert np.allclose(ts.kelvin, r.kelvin) and 293 < ts.kelvin.mean() < 300


def test_warm_up_with_sensor_is_found_on_the_temperature_channel(targets):
    floor = run(targets, seed=1)["holdout_rms_before_m"]
    doc = run(targets, [drift()], seed=1)
    assert [(f["effect"], f["location"]) for f in doc["findings"]] == [("thermal_drift", "temperature link2")]
    f = doc["findings"][0]
    assert f["confidence"] == "high" and [p["unit"] for p in f["parameters"]] == ["m/K"] * 3
    for p, g in zip(f["parameters"], G):
        if g:
            assert abs(p["value"] - g) < 0.2 * g  # within 20 %
            assert abs(p["value"] - g) < 1.96 * p["std"] or abs(p["value"] - g) < 0.05 * g  # inside its 95 % CI
    assert doc["holdout_rms_after_m"] < 1.2 * floor
    assert doc["unexplained"] is False
    plot = f["plots"][0]
    assert plot["x_label"].startswith("temperature rise of link2") and max(plot["x"]) > 5.0


def test_same_warm_up_without_sensor_leaves_the_linear_time_model_short(targets):
    """The honest outcome: the drift is found against time (named thermal_drift@campaign, high
    confidence), but the straight line cannot follow the exponential warm-up: structure stays
    in time in most runs (mostly the fast early rise) and the held-out RMS stays above what the
    temperature model reaches on the same campaign (benchmark: 1.16–1.55× the floor).  Since the diagnosis gained its verdict and link growth,
    the time structure is also caught by the finding's misspecification test (4 of these 4 seeds)."""
    unexplained_time = 0
    for seed in range(4):
        doc = run(targets, [drift()], sensor=False, seed=seed, n_boot=10)
        assert ("thermal_drift", "campaign") in {(f["effect"], f["location"]) for f in doc["findings"]}
        # located by the lack of fit, or by the finding's own misspecification test (a flexible
        # function of time still adds to the straight line → `partially_explained`, confidence low)
        own = [f for f in doc["findings"] if (f["effect"], f["location"]) == ("thermal_drift", "campaign")][0]
        unexplained_time += (any(w["variable"] == "time_since_start_s" for w in doc["unexplained_where"])
                             or ("p_value_own_variable_structure" in own["evidence"]
                                 and doc["status"] == "partially_explained"))
        with_sensor = run(targets, [drift()], sensor=True, seed=seed, n_boot=0)
        assert with_sensor["holdout_rms_after_m"] < doc["holdout_rms_after_m"]
    assert unexplained_time >= 2


@pytest.mark.parametrize("warm", [WARM, ()], ids=["warm-up, no drift", "no warm-up"])
def test_clean_recording_with_sensor_has_no_finding(targets, warm):
    for seed in (0, 2):
        doc = run(targets, sensor=True, warm=warm, seed=seed)
        assert doc["findings"] == [] and doc["unexplained"] is False
        assert any(c["location"] == "temperature link2" for c in doc["candidates"])


def _write_temperatures(path, t_s, kelvin, contacts_at_s=(10.0,)):
    """A tiny arc-welder-shaped recording: temperature readings (raw JSON, NaN allowed) only."""
    with RecordingWriter(path) as w:
        cid = w.channel(TEMPERATURE)
        for i, (t, k) in enumerate(zip(t_s, kelvin)):
            body = json.dumps({"timestamp_ns": int(t * 1e9), "sensor": "link2", "temperature_k": k}).encode()
            w._w.add_message(cid, log_time=int(abs(t) * 1e9), data=body, publish_time=int(abs(t) * 1e9), sequence=i)
    return read_recording(path)


@pytest.mark.parametrize("kelvin, times, reason", [
    ([293.2, float("nan"), 293.4, 293.5], [0, 1, 2, 3], "record 1: temperature is NaN or inf"),
    ([293.2, 293.3, 293.4, 293.5], [0, 1, 0.5, 3], "record 2: time stamp not after the previous"),
    ([293.2, 20.3, 293.4, 293.5], [0, 1, 2, 3], "record 1: temperature 20.30 K outside the plausible"),
])
def test_bad_temperature_input_is_a_one_line_error(tmp_path, kelvin, times, reason):
    rec = _write_temperatures(tmp_path / "bad.mcap", times, kelvin)
    with pytest.raises(RobocalError) as e:
        temperature_stream(rec)
    msg = str(e.value)
    assert "\n" not in msg and str(tmp_path / "bad.mcap") in msg and f"channel {TEMPERATURE}" in msg and reason in msg
    checks = check_temperature(TEMPERATURE, rec.messages[TEMPERATURE], None)
    assert any(c.status == FAIL and reason.split(": ", 1)[1][:20] in c.message for c in checks)


def test_measurements_not_covered_by_readings_are_a_one_line_error(tmp_path):
    rec = _write_temperatures(tmp_path / "gap.mcap", np.r_[np.arange(0, 60), np.arange(200, 260)],
                              np.full(120, 293.15))
    ts = temperature_stream(rec)
    meas = np.array([30, 130, 250, 400], np.int64) * 1_000_000_000
    with pytest.raises(RobocalError, match=r"channel /touch/contact: record 11: no /arm/temperature reading"):
        rise_at(ts, meas, rec.path, "/touch/contact", records=np.array([10, 11, 12, 13]))
    assert np.allclose(rise_at(ts, meas[[0, 2]]), 0.0)


def test_cli_recording_with_sensor_is_diagnosed_from_the_file(tmp_path, targets):
    """End to end through the MCAP: the simulator's recording carries the channel, the
    diagnosis reads it (the same finding as from the in-memory table)."""
    from pipeline.cli.simulate import _write
    from pipeline.simulate.arc_welder import truth_document

    camp = replace(CAMPAIGN, rate_hz=100.0)  # a smaller file: 3000 s of encoder samples
    es = se.run(NOM, TRUE, JIG, targets, camp, Noise(), [se.parse_effect(drift())], variations(True), seed=1)
    out = tmp_path / "warm.mcap"
    _write(out, None, NOM, JIG, camp, es.sim, truth_document(TRUE, Noise(), camp, es.sim),
           se.campaign_metadata(es, camp), es.temperature.messages())
    rec = read_recording(out)
    assert len(rec.messages[TEMPERATURE]) == es.temperature.t_ns.size
    assert "warm_up" not in json.dumps(rec.metadata)  # the warm-up is truth, not in the recording
    doc = diagnose_recording(rec, Settings(n_boot=10))
    assert [(f["effect"], f["location"]) for f in doc["findings"]] == [("thermal_drift", "temperature link2")]


def test_delta_shares_the_temperature_model():
    """Delta + tracker (108 measurements, ≈ 2 min, τ = 120 s): found on the temperature channel
    with the sensor; without, a straight line in time is found instead (this short campaign
    cannot tell the two apart: both reach the floor)."""
    from pipeline.diagnose.adapters import delta as dd
    from pipeline.diagnose.adapters.touch_table import add_temperature
    from pipeline.models.delta import Delta
    from pipeline.simulate import delta_tracker as sd
    from pipeline.systems.delta_tracker import TrackerModel

    g = (3e-5, 0.0, 2e-5)
    for sensor, location in ((True, "temperature link2"), (False, "campaign")):
        var = sd.Variations(both_sides=True, passes=2, warm_up=(120.0, 5.0), temperature_sensor=sensor)
        sim = sd.simulate_effects(Delta(), sd.random_truth(np.random.default_rng(1_000_004)), sd.Campaign(seed=1),
                                  sd.Noise(), (se.parse_effect(drift(g)),), var)
        tab = {"timestamp_ns": sim.t_ns, "joint_positions": sim.q, "point": sim.point_t,
               "record": np.arange(sim.t_ns.size)}
        tab = dd.add_context(tab, sim.stream_t_ns, sim.stream_q)
        if sensor:
            tab = add_temperature(tab, sim.temperature.stream(), "mem", "/tracker/point")
        model = TrackerModel(Delta())
        doc = diagnose(model, tab, adapter=dd.adapter(model, tab))
        assert [(f["effect"], f["location"]) for f in doc["findings"]] == [("thermal_drift", location)]
        if sensor:
            gx = doc["findings"][0]["parameters"][0]
            assert abs(gx["value"] - g[0]) < 0.2 * g[0] and gx["unit"] == "m/K"


def test_acquisition_carries_temperature_event_frames(tmp_path):
    """The wire protocol's EVENT frame carries `/arm/temperature` readings like any channel."""
    from pipeline.acquire import protocol as P
    from pipeline.acquire.session import Acquisition

    t0, ms = 1_795_000_000_000_000_000, 1_000_000
    t = t0 + np.arange(2000, dtype=np.int64) * 4 * ms  # 8 s of 250 Hz samples
    q = np.zeros((t.size, 6))
    frames = [P.encode_frame(P.FrameType.HELLO, 0, t0, P.encode_json(
        {"device": "bridge", "joint_names": [f"J{i}" for i in range(1, 7)]}))]
    for seq, s in enumerate(range(0, t.size, 50)):
        frames.append(P.encode_frame(P.FrameType.SAMPLES, seq + 1, int(t[s + 49]), P.encode_samples(t[s:s + 50], q[s:s + 50])))
        if s % 250 == 0:  # one reading per second
            body = {"sensor": "link2", "location": "upper arm", "temperature_k": 293.15 + s * 1e-3}
            frames.append(P.encode_frame(P.FrameType.EVENT, 1000 + seq, int(t[s]), P.encode_event(int(t[s]), TEMPERATURE, body)))
    out = tmp_path / "acq.mcap"
    with open(out, "wb") as f:
        acq = Acquisition(RecordingWriter(f), {"bridge": "sim"})
        for i, fr in enumerate(frames):
            acq.on_bytes("bridge", fr, int(t0 + i * 20 * ms))
            if i % 25 == 0:
                acq.tick()
        acq.finish("test")
    rec = read_recording(out)
    ts = temperature_stream(rec)
    assert ts.t_ns.size == 8 and ts.sensor == "link2"
    assert np.allclose(np.diff(ts.kelvin), 0.25) and all("device_timestamp_ns" in m for m in rec.messages[TEMPERATURE])
