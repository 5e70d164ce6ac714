"""End to end over real pseudo-terminals: `robocal device-sim` → `robocal acquire` → calibrate.

Both commands run as real processes; the devices are real ttys."""

from __future__ import annotations

import numpy as np
import pytest
from stream_support import record_over_pty, simulate

from pipeline.acquire import protocol as P
from pipeline.acquire.devicesim import Clock, device_streams
from pipeline.calibrate import calibrate
from pipeline.recording.reader import read_recording

SIM_ARGS = {"arc-welder": ["--contacts", "12", "--seed", "3"], "scorbot-scanner": ["--seed", "3"],
            "delta-tracker": ["--seed", "3"]}


# the systems with serial device simulators; the tracker's is extended (`make test-extended`, CI's time budget): CI
# keeps the arc welder's and the scanner's campaigns through a pty, and the tracker's device stream through a pty in
# test_acquire_dead_device
@pytest.mark.parametrize("system", [s if s != "delta-tracker" else pytest.param(s, marks=pytest.mark.extended)
                                    for s in sorted(SIM_ARGS)])
def test_campaign_through_pty_calibrates_like_the_direct_recording(tmp_path, system):
    direct = simulate(tmp_path, system, SIM_ARGS[system])
    out, s, _ = record_over_pty(tmp_path, system, ("--recording", str(direct), "--speed", "40", "--batch", "4",
                                                   "--drift-ppm", "100", "--offset-s", "2"))
    assert s["stop_reason"] == "campaign complete"
    a, b = read_recording(direct), read_recording(out)
    assert b.complete and not b.warnings
    for name in a.metadata:  # self-contained: the devices announced every metadata document
        assert b.metadata[name] == a.metadata[name]
    for topic, msgs in a.messages.items():
        assert len(b.messages[topic]) > 0
        if topic in ("/tf", "/robot_description"):  # derived by each writer on its own clock (recording.scene)
            continue
        if topic != "/robot/joint_state":
            strip = lambda m: {k: v for k, v in m.items() if not k.endswith("_ns")}  # noqa: E731
            assert [strip(m) for m in b.messages[topic]] == [strip(m) for m in msgs]
    qa = np.concatenate([m["positions"] for m in a.messages["/robot/joint_state"]])
    qb = np.concatenate([m["positions"] for m in b.messages["/robot/joint_state"]])
    assert np.array_equal(qa, qb)
    ra = calibrate(direct, tmp_path / "cal_direct")
    rb = calibrate(out, tmp_path / "cal_acq")
    assert rb["n_measurements"] == ra["n_measurements"]
    assert rb["rms_after_m"] == pytest.approx(ra["rms_after_m"], rel=1e-9, abs=1e-12)
    assert rb["parameters"] == ra["parameters"]


def test_one_percent_corrupted_bytes(tmp_path):
    """Every clean frame kept, every damaged one counted, none written as data."""
    direct = simulate(tmp_path, "arc-welder", ["--contacts", "10", "--seed", "5"])
    out, s, rep = record_over_pty(tmp_path, "arc-welder", ("--recording", str(direct), "--speed", "40", "--corrupt",
                                                           "0.01", "--noise", "0.02", "--drop", "0.0005", "--seed", "9"),
                                  "--max-s", "60")
    dev, sent = s["devices"]["bridge"], rep["devices"]["bridge"]
    damaged = set(sent["damaged_seqs"])
    assert len(damaged) > 0.2 * sent["frames"]  # the impairment really happened
    # rebuild what the device sent, frame by frame
    rec = read_recording(direct)
    t0 = rec.messages["/robot/joint_state"][0]["timestamp_ns"]
    stream = device_streams(rec, Clock(t0=t0), batch=1)["bridge"]
    last = dev["last_seq"]  # the host stops reading once the campaign is complete
    clean = [k for k in range(last + 1) if k not in damaged]
    # every damaged frame between clean ones is counted missing (with its position)
    inner_damaged = {k for k in damaged if min(clean) < k < last}
    assert dev["missing_frames"] == len(inner_damaged)
    assert dev["frames"] == len(clean)
    missing = {m for first, n, _ in dev["missing_ranges"] for m in range(first, first + n)}
    assert missing == inner_damaged
    assert dev["bad_frames"] > 0 and dev["garbage_bytes"] > 0
    # the recorded samples are exactly those of the clean SAMPLES frames, bit for bit
    want_t, want_q = [], []
    for k in clean:
        if stream.kinds[k] == P.FrameType.SAMPLES:
            (f,), _ = P.FrameDecoder().feed(stream.frames[k])
            t, q = P.decode_samples(f.payload)
            want_t.append(t)
            want_q.append(q)
    got = read_recording(out)
    msgs = got.messages["/robot/joint_state"]
    assert np.array_equal(np.concatenate([m["device_timestamps_ns"] for m in msgs]), np.concatenate(want_t))
    assert np.array_equal(np.concatenate([m["positions"] for m in msgs]), np.concatenate(want_q))
    want_contacts = [P.decode_event(P.FrameDecoder().feed(stream.frames[k])[0][0].payload)[2]["face"]
                     for k in clean if stream.kinds[k] == P.FrameType.EVENT]
    assert len(got.messages.get("/touch/contact", [])) == len(want_contacts)
    assert [m["face"] for m in got.messages.get("/touch/contact", [])] == want_contacts


def test_disconnects_are_retried_and_logged_as_gaps(tmp_path):
    direct = simulate(tmp_path, "arc-welder", ["--contacts", "10", "--seed", "2"])
    out, s, rep = record_over_pty(tmp_path, "arc-welder", ("--recording", str(direct), "--speed", "25",
                                                           "--disconnect-every", "1.0", "--disconnect-for", "0.4"),
                                  "--max-s", "60")
    dev, sent = s["devices"]["bridge"], rep["devices"]["bridge"]
    assert s["stop_reason"] == "campaign complete"
    assert len(sent["disconnects"]) >= 2
    assert len(dev["gaps"]) == len(sent["disconnects"])
    # lost: every frame due while unplugged, plus what was still in the pty buffer at the unplug
    lost = np.array(sent["lost_seqs"])
    missing = {m for first, n, _ in dev["missing_ranges"] for m in range(first, first + n)}
    assert set(lost.tolist()) <= missing and dev["missing_frames"] == len(missing)
    for k in missing - set(lost.tolist()):
        ahead = lost[lost > k]
        assert ahead.size and ahead[0] - k <= 600, f"frame {k} lost away from any unplug"
    assert dev["bad_frames"] <= len(sent["disconnects"])  # at most the frame cut by each unplug
    rec = read_recording(out)
    assert rec.complete
    gaps = [v for k, v in rec.metadata.items() if k.startswith("robocal.acquisition.gap.")]
    assert len(gaps) == len(sent["disconnects"])
    for g, (down, up) in zip(sorted(gaps, key=lambda g: g["start_ns"]), sent["disconnects"]):
        assert g["device"] == "bridge" and g["end_ns"] > g["start_ns"]
        assert abs(g["start_ns"] - down) < 0.3e9 and g["end_ns"] >= up - 0.3e9
    ts = np.concatenate([m["timestamps_ns"] for m in rec.messages["/robot/joint_state"]])
    assert np.all(np.diff(ts) > 0)
    assert np.diff(ts).max() > 0.3e9  # the gap is visible in the stream


def test_device_sim_simulates_the_campaign_itself(tmp_path):
    """Without --recording, device-sim runs `robocal simulate SYSTEM` with the same seed."""
    direct = simulate(tmp_path, "arc-welder", ["--contacts", "10", "--seed", "4"])
    out, _, _ = record_over_pty(tmp_path, "arc-welder", ("--seed", "4", "--sim-args", "--contacts 10", "--speed", "60",
                                                       "--batch", "8"))
    a, b = read_recording(direct), read_recording(out)
    assert [m["joint_positions"] for m in a.messages["/touch/contact"]] == \
        [m["joint_positions"] for m in b.messages["/touch/contact"]]
