"""Drive state over the serial protocol: SAMPLES_DRIVE frames, device-sim → pty → acquire.

The source recording comes from the independent generator `independent_drive` (joint j2 compliant under
a payload the URDF lacks; commanded positions, efforts and motor currents at standstill around each
measurement).  `robocal device-sim` plays it over a real pseudo-terminal and `robocal acquire` records
it: every sample's drive arrays arrive bit for bit (matched by device time), a damaged or short drive
frame is counted and never written, the rest intact, and the diagnosis of the acquired recording
finds what it finds on the source: j2's compliance from the measured torque.
"""

from __future__ import annotations

import subprocess
import threading
from pathlib import Path

import numpy as np
import pytest

import independent_drive as gen
from stream_support import ROBOCAL, bits, record_over_pty
from pipeline.acquire import protocol as P
from pipeline.acquire.devicesim import Clock, device_streams, play
from pipeline.diagnose import Settings, diagnose
from pipeline.diagnose.adapters.urdf_robot import adapter, from_recording
from pipeline.importers.recording import T0_NS, write_urdf_recording
from pipeline.ingest.streams import JOINT_STATE, joint_stream
from pipeline.recording import joint_state_batch as JSB
from pipeline.recording.reader import read_recording
from test_drive_state import DESC, K_NM_PER_A, URDF
from test_urdf_diagnose import point_campaign

ROOT = Path(__file__).resolve().parents[1]
C_J2, PAYLOAD_KG = 2e-6, 10.0  # rad/(N·m), kg (not in the URDF)
N_MEAS, SPACING_NS = 16, 500_000_000  # 0.3 s standstill dwell per measurement, 8 s of campaign


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    """An independent drive campaign (seed 0) with all three drive arrays in its stream."""
    path = tmp_path_factory.mktemp("drive") / "source.mcap"
    c = np.r_[0.0, C_J2, 0, 0, 0, 0]
    _, table = point_campaign(lambda q: gen.deflected(q, c, PAYLOAD_KG), 0, N_MEAS, 2e-5, text=URDF)
    q = table["joint_positions"]
    t = T0_NS + np.arange(N_MEAS, dtype=np.int64) * SPACING_NS
    stream = gen.standstill_stream(t, q, gen.holding_efforts(gen.deflected(q, c, PAYLOAD_KG), PAYLOAD_KG),
                                   np.random.default_rng(99), 0.05)
    stream["current"] = stream["effort"] / K_NM_PER_A
    tab = {"joint_positions": q, "position": table["position"], "target": table["target"], "timestamp_ns": t}
    write_urdf_recording(path, DESC, "point", {"n_targets": 1}, tab, stream=stream)
    return path


def device_time_index(src: Path, clock: dict) -> tuple[np.ndarray, JSB.Batches]:
    """The source stream and each of its samples' device times (the device clock of device-sim's report)."""
    b = JSB.decode(read_recording(src).messages.raw[JOINT_STATE])
    return Clock(clock["t0"], clock["offset_ns"], clock["drift"])(b.t_ns), b


def assert_drive_matches(acq: Path, src_dev_t: np.ndarray, src: JSB.Batches, expected: np.ndarray) -> None:
    """The acquired stream holds exactly the source samples `expected` (indices), each with its
    positions and drive arrays bit for bit, at strictly increasing corrected times."""
    b = JSB.decode(read_recording(acq).messages.raw[JOINT_STATE])
    assert np.all(np.diff(b.t_ns) > 0)
    k = np.searchsorted(src_dev_t, b.device_t_ns)
    assert np.array_equal(k, expected) and np.array_equal(src_dev_t[k], b.device_t_ns)
    for key in ("q", "q_cmd", "effort", "current"):
        assert np.array_equal(bits(getattr(b, key)), bits(getattr(src, key)[k])), key


# ----- the frame ---------------------------------------------------------------------------------------
def test_samples_drive_payload_round_trips_bit_for_bit_and_a_wrong_length_is_an_error():
    rng = np.random.default_rng(1)
    n, nj = 37, 6
    t = np.cumsum(rng.integers(1, 10**7, n)).astype(np.int64)
    q = rng.normal(0, 2, (n, nj))
    arrays = {k: rng.normal(0, 50, (n, nj)) for k in P.DRIVE_FIELDS}
    arrays["effort"][0, 0], arrays["current"][1, 1], arrays["q_cmd"][2, 2] = -0.0, 5e-324, np.finfo(float).max
    for subset in ([], ["effort"], ["q_cmd", "current"], list(P.DRIVE_FIELDS)):
        payload = P.encode_samples_drive(t, q, {k: arrays[k] for k in subset})
        assert len(payload) == P.samples_drive_size(n, nj, len(subset))
        t2, q2, d = P.decode_any_samples(P.FrameType.SAMPLES_DRIVE, payload)
        assert np.array_equal(t2, t) and np.array_equal(bits(q2), bits(q)) and list(d) == subset
        for k in subset:
            assert np.array_equal(bits(d[k]), bits(arrays[k]))
        for bad in (payload[:-8], payload + b"\0" * 8, payload[:-1]):
            with pytest.raises(ValueError, match="does not hold"):
                P.decode_samples_drive(bad)
    full = bytearray(P.encode_samples_drive(t, q, arrays))
    full[3] |= 0x08  # an undefined flag bit
    with pytest.raises(ValueError, match="undefined"):
        P.decode_samples_drive(bytes(full))
    # a plain SAMPLES payload still decodes as before, with no drive state
    t3, q3, d3 = P.decode_any_samples(P.FrameType.SAMPLES, P.encode_samples(t, q))
    assert np.array_equal(t3, t) and np.array_equal(q3, q) and d3 == {}
    # the largest frame a device may send fits the protocol's payload limit, one more sample does not
    m = P.max_drive_samples(nj, 3)
    big = np.zeros((m + 1, nj))
    P.encode_frame(P.FrameType.SAMPLES_DRIVE, 0, 0, P.encode_samples_drive(np.arange(m), big[:m], {"effort": big[:m],
                   "q_cmd": big[:m], "current": big[:m]}))
    with pytest.raises(ValueError, match="exceeds"):
        P.encode_frame(P.FrameType.SAMPLES_DRIVE, 0, 0, P.encode_samples_drive(np.arange(m + 1), big, {
            "effort": big, "q_cmd": big, "current": big}))


def test_device_sim_sends_drive_frames_only_for_a_stream_with_drive_state(source):
    old = read_recording(ROOT / "recordings" / "arc-welder-touch-pb.mcap")
    (bridge,) = device_streams(old, Clock(t0=0), batch=4).values()
    kinds = set(bridge.kinds)
    assert P.FrameType.SAMPLES in kinds and P.FrameType.SAMPLES_DRIVE not in kinds
    streams = device_streams(read_recording(source), Clock(t0=0), batch=1000)
    kinds = streams["bridge"].kinds
    assert P.FrameType.SAMPLES not in kinds and P.FrameType.SAMPLES_DRIVE in kinds
    hello = next(P.decode_json(P.FrameDecoder().feed(f)[0][0].payload) for f, k in zip(streams["bridge"].frames, kinds)
                 if k == P.FrameType.HELLO)
    assert hello["drive_state"] == list(P.DRIVE_NAMES)
    sizes = [P.FrameDecoder().feed(f)[0][0].payload for f, k in zip(streams["bridge"].frames, kinds)
             if k == P.FrameType.SAMPLES_DRIVE]
    assert max(len(p) for p in sizes) <= P.MAX_PAYLOAD  # --batch 1000 split to what a frame holds


# ----- through a real pty ------------------------------------------------------------------------------
def test_drive_state_through_pty_bit_for_bit_and_the_diagnosis_is_the_sources(tmp_path, source):
    """Real time (drive windows are host-time windows: see docs/guide/acquire.md), a drifting, offset clock."""
    out, s, rep = record_over_pty(tmp_path, "urdf", ("--recording", str(source), "--speed", "1", "--batch", "4",
                                                     "--drift-ppm", "100", "--offset-s", "2"))
    dev = s["devices"]["bridge"]
    assert s["stop_reason"] == "campaign complete" and dev["drive_state"] == list(P.DRIVE_NAMES)
    assert dev["bad_frames"] == dev["missing_frames"] == dev["rejected_frames"] == 0
    src_dev_t, src = device_time_index(source, rep["clock"])
    assert_drive_matches(out, src_dev_t, src, np.arange(src_dev_t.size))
    a, b = read_recording(source), read_recording(out)
    assert b.complete and [m["position"] for m in b.messages["/measure/point"]] == \
        [m["position"] for m in a.messages["/measure/point"]]
    docs, tabs = [], []
    for rec in (a, b):
        model, tab, _ = from_recording(rec)
        tabs.append(tab)
        docs.append(diagnose(model, tab, settings=Settings(n_boot=10, sign_flips=0), adapter=adapter(model, tab, held=())))
    assert np.array_equal(bits(tabs[1]["joint_efforts"]), bits(tabs[0]["joint_efforts"]))
    (fa,), (fb,) = docs[0]["findings"], docs[1]["findings"]
    assert (fb["effect"], fb["location"], fb["source"]) == (fa["effect"], fa["location"], fa["source"]) == \
        ("joint_compliance", "j2", "measured torque")
    assert fb["parameters"][0]["value"] == pytest.approx(fa["parameters"][0]["value"], rel=1e-6)
    assert abs(fb["parameters"][0]["value"] / C_J2 - 1) < 0.15
    assert docs[1]["holdout_rms_after_m"] == pytest.approx(docs[0]["holdout_rms_after_m"], rel=1e-6)


def test_damaged_drive_frames_are_counted_and_never_written(tmp_path, source):
    """Flipped and dropped bytes (0.05 %, 0.01 %: a third of the ~830-byte drive frames damaged) and line
    noise: the recording holds exactly the samples of the clean drive frames, bit for bit."""
    out, s, rep = record_over_pty(tmp_path, "urdf", ("--recording", str(source), "--speed", "20", "--batch", "4",
                                                     "--corrupt", "0.0005", "--drop", "0.0001", "--noise", "0.02",
                                                     "--seed", "9"), "--max-s", "60")
    dev, sent = s["devices"]["bridge"], rep["devices"]["bridge"]
    damaged = set(sent["damaged_seqs"])
    c = rep["clock"]
    stream = device_streams(read_recording(source), Clock(c["t0"], c["offset_ns"], c["drift"]), batch=4)["bridge"]
    drive_seqs = [k for k, kind in enumerate(stream.kinds) if kind == P.FrameType.SAMPLES_DRIVE]
    assert len(damaged & set(drive_seqs)) > 0.2 * len(drive_seqs)  # the impairment really hit drive frames
    assert dev["bad_frames"] > 0 and dev["rejected_frames"] == 0
    clean = [k for k in drive_seqs if k not in damaged and k <= dev["last_seq"]]
    want_t = np.concatenate([P.decode_samples_drive(P.FrameDecoder().feed(stream.frames[k])[0][0].payload)[0]
                             for k in clean])
    src_dev_t, src = device_time_index(source, c)
    assert_drive_matches(out, src_dev_t, src, np.searchsorted(src_dev_t, want_t))


def test_drive_state_across_disconnects(tmp_path, source):
    """The bridge unplugged every second for 0.4 s: each gap logged, every drive frame not lost arrives
    whole (its samples' drive arrays bit for bit), none of a lost one."""
    out, s, rep = record_over_pty(tmp_path, "urdf", ("--recording", str(source), "--speed", "2", "--batch", "4",
                                                     "--disconnect-every", "1.0", "--disconnect-for", "0.4"),
                                  "--max-s", "60")
    dev, sent = s["devices"]["bridge"], rep["devices"]["bridge"]
    assert s["stop_reason"] == "campaign complete" and len(sent["disconnects"]) >= 2
    assert len(dev["gaps"]) == len(sent["disconnects"])
    missing = {m for first, n, _ in dev["missing_ranges"] for m in range(first, first + n)}
    assert set(sent["lost_seqs"]) <= missing
    c = rep["clock"]
    stream = device_streams(read_recording(source), Clock(c["t0"], c["offset_ns"], c["drift"]), batch=4)["bridge"]
    got = [k for k, kind in enumerate(stream.kinds) if kind == P.FrameType.SAMPLES_DRIVE and k not in missing
           and k <= dev["last_seq"]]
    want_t = np.concatenate([P.decode_samples_drive(P.FrameDecoder().feed(stream.frames[k])[0][0].payload)[0]
                             for k in got])
    src_dev_t, src = device_time_index(source, c)
    assert want_t.size < src_dev_t.size  # samples were lost
    assert_drive_matches(out, src_dev_t, src, np.searchsorted(src_dev_t, want_t))


def test_a_short_drive_frame_with_a_valid_checksum_is_rejected_the_rest_intact(tmp_path, source):
    """Three frames whose checksums hold but whose content is wrong: a drive frame 8 bytes short (its
    header declares more), one with an undefined flag bit, a plain SAMPLES frame in a drive stream.
    Each is counted as rejected and none of their samples is written; every other sample is."""
    rec = read_recording(source)
    t0 = int(JSB.decode(rec.messages.raw[JOINT_STATE]).t_ns[0])
    clock = Clock(t0=t0)
    stream = device_streams(rec, clock, batch=4)["bridge"]
    drive_seqs = [k for k, kind in enumerate(stream.kinds) if kind == P.FrameType.SAMPLES_DRIVE]
    spoilt = drive_seqs[10], drive_seqs[len(drive_seqs) // 2], drive_seqs[-10]
    lost = []
    for k, how in zip(spoilt, ("short", "flag", "plain")):
        (f,), _ = P.FrameDecoder().feed(stream.frames[k])
        t, q, _ = P.decode_samples_drive(f.payload)
        lost.append(t)
        payload = {"short": f.payload[:-8], "flag": f.payload[:3] + bytes([f.payload[3] | 0x80]) + f.payload[4:],
                   "plain": P.encode_samples(t, q)}[how]
        kind = P.FrameType.SAMPLES if how == "plain" else P.FrameType.SAMPLES_DRIVE
        stream.frames[k] = P.encode_frame(kind, f.seq, f.device_time_ns, payload)
    out, link_dir = tmp_path / "acq.mcap", tmp_path / "dev"
    cmd = [ROBOCAL, "acquire", "--out", str(out), "--summary", str(tmp_path / "s.json"), "--device",
           f"bridge={link_dir / 'bridge'}", "--max-s", "60"]
    host = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    player = threading.Thread(target=play, args=({"bridge": stream}, link_dir),
                              kwargs={"speed": 20.0, "announce": lambda _: None})
    player.start()
    _, err = host.communicate(timeout=120)
    player.join(timeout=60)
    assert host.returncode == 0, err
    import json

    dev = json.loads((tmp_path / "s.json").read_text())["devices"]["bridge"]
    assert dev["rejected_frames"] == 3 and dev["bad_frames"] == dev["missing_frames"] == 0
    reasons = [p["reason"] for p in dev["problems"] if p["kind"] == "rejected"]
    assert any("does not hold" in r for r in reasons) and any("undefined" in r for r in reasons)
    assert any(r.startswith("SAMPLES: drive state none after") for r in reasons)
    src_dev_t, src = device_time_index(source, {"t0": t0, "offset_ns": 0, "drift": 0.0})
    keep = ~np.isin(src_dev_t, np.concatenate(lost))
    assert keep.sum() == src_dev_t.size - 12
    assert_drive_matches(out, src_dev_t, src, np.flatnonzero(keep))
    assert len(read_recording(out).messages["/measure/point"]) == N_MEAS
    assert joint_stream(read_recording(out)).effort is not None
