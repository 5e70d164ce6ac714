"""The recording contract's gaps (payload changes, search commands, faults), on recordings written by the independent generator's own
MCAP writer (`tests/independent_recording.py`, following `schemas/` only): payload changes logged when
they happen, each contact's search command, a search the controller aborted; old recordings without
them stay readable."""

from __future__ import annotations

import numpy as np
import pytest

import independent_recording as ir
import independent_touch as it
from pipeline.diagnose import Settings
from pipeline.diagnose.stage import diagnose_recording
from pipeline.diagnose.adapters.touch_table import from_recording
from pipeline.models.jig import stepped_block
from pipeline.recording.reader import read_recording
from pipeline.recording.schemas import CHANNELS, validator
from pipeline.systems import arc_welder as aw

SETTINGS = Settings(n_boot=0, repeatability_3sigma_m=1e-4)


@pytest.fixture(scope="module")
def world():
    nom, tru = it.default_arms()
    return nom, tru, it.plan(nom, it.stepped_block(), m=110, seed=1)


def _write(tmp_path, c, name="rec.mcap", **kw):
    path = tmp_path / name
    ir.write_recording(path, c, aw.nominal_arm().to_dict(), stepped_block().to_dict(), **kw)
    return read_recording(path)


def test_every_message_follows_its_schema(world, tmp_path):
    c = it.run(*world, seed=5)
    rec = _write(tmp_path, c, faulted=[10])
    for topic in ("/touch/contact", "/arm/payload", "/touch/miss"):
        msgs = rec.messages[topic]
        assert msgs
        for m in msgs:
            validator(CHANNELS[topic]).validate(m)


def test_payload_follows_the_changes_as_logged_not_the_programmed_schedule(world, tmp_path):
    """The operator changed the payload 3 contacts after each programmed block boundary: the table
    follows the `/arm/payload` events; a recording without them falls back to the campaign's schedule."""
    c = it.run(*world, seed=6, payload_late=3)
    truth = c.payload_kg  # the generator's own payload per contact, not the diagnosis's table builder
    _, tab, info = from_recording(_write(tmp_path, c))
    assert info["payload_from"] == "events"
    assert np.array_equal(tab["payload_kg"], truth)
    _, old, info_old = from_recording(_write(tmp_path, c, "old.mcap", events=False, search=False))
    assert info_old["payload_from"] == "campaign schedule"
    assert "search_speed_m_s" not in old  # an old recording: no search command, still readable
    wrong = np.flatnonzero(old["payload_kg"] != truth)
    assert wrong.size == 9 * 3  # 3 contacts at each of the 9 block boundaries after the first block
    assert np.array_equal(old["joint_positions"], tab["joint_positions"])


def test_a_stream_glitch_is_caught_by_the_commanded_search_speed(world, tmp_path):
    """J1 reads 4 mrad off over the 30 ms before one latch: the derived approach speed is a few cm/s
    (below the 0.25 m/s any search stays under), but far from that contact's commanded speed."""
    c = it.run(*world, (it.Effect("glitch", 0.004, {"record": 52}),), seed=7)
    doc = diagnose_recording(_write(tmp_path, c), SETTINGS)
    hit = [o for o in doc["outlier_records"] if o["record"] == 52]
    assert hit and "commanded search speed" in hit[0]["reason"], doc["outlier_records"]
    assert len(doc["outlier_records"]) == 1
    old = diagnose_recording(_write(tmp_path, c, "old.mcap", search=False), SETTINGS)
    assert not any("commanded" in o["reason"] for o in old["outlier_records"])


def test_a_faulted_search_is_reported_and_its_contact_left_out(world, tmp_path):
    c = it.run(*world, seed=8)
    rec = _write(tmp_path, c, faulted=[10, 44])
    _, tab, _ = from_recording(rec)
    assert len(tab["timestamp_ns"]) == 98
    doc = diagnose_recording(rec, SETTINGS)
    sw = doc["searches_without_contact"]
    assert sw["counts"] == {"fault": 2}
    assert [f["fault_code"] for f in sw["faults"]] == ["E-STOP 112"] * 2
    assert doc["n_measurements"] == 98 and doc["status"] == "clean"


def test_several_temperature_sensors_the_growth_is_named_on_the_sensor_that_tracks_it(world, tmp_path):
    """a2, d4 grow as the upper arm warms up (1 − e^(−t/300 s)); two sensors are logged: the base (the
    hall's slow drift) first, then link2, which follows the warm-up.  Both become table columns; the
    growth is named against link2's temperature (linear in it: the right form), back to the floor."""
    nom, tru, targets = world
    sigma = it.run(nom, tru, targets, (), seed=0).along_normal_noise_sigma_m
    form = it.Effect("thermal_growth", 1.0, {"tau_s": 300.0})
    c = it.run(nom, tru, targets, (it.Effect(form.kind, 4 * it.mds(nom, tru, targets, form, sigma), form.where),),
               seed=9)
    clean = diagnose_recording(_write(tmp_path, it.run(nom, tru, targets, (), seed=9), "clean.mcap"), SETTINGS)
    t0 = (c.contacts["timestamp_ns"][0] - c.stream_t_ns[0]) * 1e-9
    temps = {"base": lambda t: 293.15 + 0.2 * t / 1000, "link2": lambda t: 296.0 + 12.0 * (1 - np.exp(-t / 300.0))}
    rec = _write(tmp_path, c, "warm.mcap", temperatures=temps)
    _, tab, _ = from_recording(rec)
    assert tab["temperature_sensor"][0] == "base" and "temperature_rise_K@link2" in tab
    assert t0 < 30 and np.allclose(tab["temperature_rise_K@link2"][-1], 12.0 * (1 - np.exp(-tab["time_since_start_s"][-1] / 300)),
                                   atol=0.05)
    doc = diagnose_recording(rec, SETTINGS)
    assert [(f["effect"], f["location"]) for f in doc["findings"]] == [("thermal_growth", "links (temperature link2)")]
    assert doc["status"] == "explained"
    assert doc["holdout_rms_after_m"] <= 1.2 * clean["holdout_rms_before_m"]
