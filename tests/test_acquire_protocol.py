"""Wire protocol v1: frame codec, resynchronisation after garbage, corruption accounting."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.acquire import protocol as P
from pipeline.acquire.devicesim import impair

frame_spec = st.tuples(st.sampled_from(list(P.FrameType)), st.integers(-(2**63), 2**63 - 1),
                       st.binary(max_size=300))


def _decode_all(stream: bytes, cuts: list[int]) -> tuple[list[P.Frame], P.FrameDecoder]:
    dec = P.FrameDecoder()
    frames = []
    pos = 0
    for c in sorted(set(cuts)) + [len(stream)]:
        f, _ = dec.feed(stream[pos:c])
        frames += f
        pos = c
    dec.finish()
    return frames, dec


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(frame_spec, st.binary(max_size=64)), min_size=1, max_size=20),
       st.lists(st.integers(0, 20_000), max_size=8))
def test_every_frame_survives_arbitrary_garbage_between_frames(items, cuts):
    """Garbage (any bytes, including sync words and fake headers) between frames, and the
    stream delivered in arbitrary pieces: every frame comes out, intact and in order."""
    stream = b""
    offsets = []
    for seq, ((ftype, dtime, payload), junk) in enumerate(items):
        stream += junk
        offsets.append(len(stream))
        stream += P.encode_frame(ftype, seq, dtime, payload)
    frames, dec = _decode_all(stream, cuts)
    assert [(f.type, f.seq, f.device_time_ns, f.payload) for f in frames] == \
           [(t, s, d, p) for s, ((t, d, p), _) in enumerate(items)]
    assert [f.offset for f in frames] == offsets
    assert dec.garbage_bytes == sum(len(j) for _, j in items)


@settings(max_examples=100, deadline=None)
@given(st.lists(frame_spec, min_size=5, max_size=40), st.integers(0, 2**32 - 1))
def test_damaged_frames_are_never_returned_and_clean_ones_always_are(specs, seed):
    """1 % of bytes flipped and 0.2 % dropped: the frames returned are exactly the undamaged
    ones, and the sequence numbers account for every damaged one."""
    rng = np.random.default_rng(seed)
    stream, damaged, sent = b"", set(), {}
    for seq, (ftype, dtime, payload) in enumerate(specs):
        b, bad = impair(P.encode_frame(ftype, seq, dtime, payload), rng, 0.01, 0.002, 0.05)
        stream += b
        sent[seq] = (ftype, dtime, payload)
        if bad:
            damaged.add(seq)
    frames, _ = _decode_all(stream, [])
    got = {f.seq: (f.type, f.device_time_ns, f.payload) for f in frames}
    assert set(got) == set(sent) - damaged
    assert all(got[s] == sent[s] for s in got)
    tr = P.SeqTracker()
    for f in frames:
        tr.see(f.seq, f.offset)
    # frames lost in the middle are counted as missing (a damaged head or tail has no later/earlier frame)
    if got:
        inner = {s for s in damaged if min(got) < s < max(got)}
        assert tr.missing == len(inner)


def test_corrupted_length_does_not_swallow_following_frames():
    a = P.encode_frame(P.FrameType.HEARTBEAT, 0, 1, b"")
    b = P.encode_frame(P.FrameType.EVENT, 1, 2, b"x" * 50)
    bad = bytearray(a)
    bad[16:18] = (60_000).to_bytes(2, "little")  # length field says 60 kB
    dec = P.FrameDecoder()
    frames, problems = dec.feed(bytes(bad) + b)
    assert [f.seq for f in frames] == [1]  # b arrives at once, not after 60 kB
    assert any(isinstance(p, P.BadFrame) and p.offset == 0 and p.reason == "header checksum" for p in problems)


def test_payload_checksum_failure_is_reported_with_its_position():
    a = P.encode_frame(P.FrameType.SAMPLES, 7, 1, P.encode_samples(np.array([1, 2]), np.ones((2, 6))))
    bad = bytearray(a)
    bad[40] ^= 0x10
    junk = b"\x00\xa5"
    frames, problems = P.FrameDecoder().feed(junk + bytes(bad) + a)
    assert [f.seq for f in frames] == [7]
    assert frames[0].offset == len(junk) + len(bad)
    assert P.BadFrame(len(junk), "payload checksum") in problems


def test_seq_tracker_counts_gaps_and_wraps():
    tr = P.SeqTracker()
    for s, off in [(P.SEQ_MOD - 2, 0), (P.SEQ_MOD - 1, 10), (3, 20), (4, 30)]:
        tr.see(s, off)
    assert tr.missing == 3 and tr.gaps == [(0, 3, 20)]


def test_payload_codecs_round_trip():
    t = np.array([10, 20, 30], np.int64)
    q = np.arange(18, dtype=float).reshape(3, 6) / 7
    t2, q2 = P.decode_samples(P.encode_samples(t, q))
    assert np.array_equal(t, t2) and np.array_equal(q, q2)
    assert P.decode_event(P.encode_event(-5, "/touch/contact", {"face": "top", "axis": "z"})) == \
        (-5, "/touch/contact", {"face": "top", "axis": "z"})
    doc = '{"a": "' + "é" * 1000 + '"}'
    parts = P.encode_meta_parts("robocal.fixture", doc, part_size=100)
    asm = P.MetaAssembler()
    done = [asm.add(p) for p in reversed(parts + parts[:3])]  # repeated, out of order
    assert [d for d in done if d] == [("robocal.fixture", doc)]
