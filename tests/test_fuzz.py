"""In-suite fuzzing — a seeded mutation corpus over the bundled recordings (every class of
tests/fuzz_corpus.py) through ingest and validate, one case of every kind of edit of the other
surfaces (tests/fuzz_surfaces.py: CSV, URDF, ROS 2 bags, campaign and target files, run folders,
archives, …), and hypothesis properties over the reader and the decoders.  Zero tracebacks, hangs,
runs over 1 GB, silent losses or changed user files.  Bounded (≈ 2 min); the full-size run is
benchmarks/bench_fuzz.py."""

from __future__ import annotations

import json
from collections import Counter

from hypothesis import HealthCheck, example, given, settings, strategies as st

from fuzz_corpus import CLASSES, cases, classify_inprocess, message_count
from hostile_support import BUNDLED
from pipeline.errors import RobocalError
from pipeline.recording import framing
from pipeline.recording.reader import decode, read_recording

FAILURES = ("traceback", "hang", "memory", "silent-loss")


def _status_kb(field: str) -> int:
    return int(next(ln.split()[1] for ln in open("/proc/self/status") if ln.startswith(field)))


def test_mutation_corpus_every_class(tmp_path):
    rss0 = _status_kb("VmRSS:")
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")  # reset the peak (VmHWM) to the current RSS
    except OSError:
        pass
    originals = {s: message_count(BUNDLED[s]) for s in ("delta-tracker", "scorbot-scanner")}
    table: Counter = Counter()
    bad = []
    for i, case in enumerate(cases(seed=15, per_class=6)):
        path = case.make(tmp_path)
        outcome, detail = classify_inprocess(path, tmp_path / f"run{i}", originals[case.source])
        table[case.cls, outcome] += 1
        if outcome in FAILURES:
            bad.append((case.name, outcome, detail))
    assert {c for c, _ in table} == set(CLASSES)
    assert not bad, bad
    assert _status_kb("VmHWM:") - rss0 < 1_000_000  # kB: under 1 GB more, bombs included


def test_surface_corpus_every_class(tmp_path):
    """One case of every kind of edit of every surface beyond the recordings (CSV, URDF, ROS 2 bags,
    campaign and target files, run folders, archives, recordings missing their topic or running
    backwards, command-line counts, figures, nonsense options, recordings at an output path):
    one-line errors, successes that say what they lost, never a traceback, hang, a user's file
    changed or nonsense accepted."""
    from fuzz_surfaces import FAILURES as SURFACE_FAILURES, PERIOD, SURFACES, classify, surface_cases

    table: Counter = Counter()
    bad = []
    for i, case in enumerate(surface_cases(seed=2)):
        outcome, detail = classify(case, tmp_path / f"s{i}")
        table[case.cls, outcome] += 1
        if outcome in SURFACE_FAILURES:
            bad.append((case.name, outcome, detail))
    assert not bad, bad
    assert {c for c, _ in table} == set(SURFACES)
    assert table["ros2bag", "warned"] >= 1 and table["csv", "error"] >= 8 and table["runfolder", "error"] >= 5
    # nonsense options and an existing recording at every writer's output: each refused in one line
    assert table["options", "error"] == PERIOD["options"] and table["outputs", "error"] == PERIOD["outputs"]


GOOD = BUNDLED["delta-tracker"].read_bytes()


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=4096))
def test_reader_on_any_bytes_after_the_magic(tmp_path, data):
    p = tmp_path / "any.mcap"
    p.write_bytes(framing.MAGIC + data)
    try:
        rec = read_recording(p)
    except RobocalError as e:
        assert "\n" not in str(e) and str(p) in str(e)
        return
    assert rec.complete or rec.warnings


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(8, len(GOOD)), flips=st.lists(st.tuples(st.integers(8, len(GOOD) - 1), st.integers(0, 7)),
                                                     max_size=8))
@example(cut=45, flips=[(8, 0), (8, 1)])  # the header's opcode turned into a footer's: not a closed file
def test_reader_keeps_only_true_messages_of_a_damaged_file(tmp_path, cut, flips):
    """Whatever the damage, every message read is one of the file's own, in order per channel,
    and anything missing is announced by a warning."""
    b = bytearray(GOOD)
    for pos, bit in flips:
        b[pos] ^= 1 << bit
    p = tmp_path / "d.mcap"
    p.write_bytes(bytes(b[:cut]))
    full = read_recording(BUNDLED["delta-tracker"])
    try:
        rec = read_recording(p)
    except RobocalError as e:
        assert "\n" not in str(e) and str(p) in str(e)
        return
    lost = 0
    for topic, msgs in rec.messages.raw.items():
        ref = full.messages.raw.get(topic, [])
        it = iter(ref)
        assert all(any(m == r for r in it) for m in msgs), topic  # a subsequence of the true messages
        lost += len(ref) - len(msgs)
    lost += sum(len(v) for t, v in full.messages.raw.items() if t not in rec.messages.raw)
    if lost > 0:
        assert rec.warnings


JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
                    lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=8), c, max_size=4),
                    max_leaves=20)


@settings(max_examples=300, deadline=None)
@given(body=st.binary(max_size=200) | JSON.map(lambda v: json.dumps(v).encode()))
def test_decode_raises_only_value_errors(body):
    try:
        decode(body)
    except (ValueError, UnicodeDecodeError):
        pass


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(bodies=st.lists(JSON | st.fixed_dictionaries(
    {"timestamp_ns": st.integers() | st.floats(), "timestamps_ns": st.lists(st.integers() | st.floats(), max_size=3),
     "joint_names": st.lists(st.text(max_size=3), max_size=3) | JSON,
     "positions": st.lists(st.lists(st.floats() | st.integers(), max_size=3), max_size=3) | JSON}), min_size=1, max_size=4))
def test_joint_stream_decoders_fail_only_as_ingest_expects(bodies):
    """The encoder-stream decoders return a stream or raise what ingest turns into a named error."""
    from pipeline.ingest.guards import first_schema_error
    from pipeline.ingest.streams import JOINT_STATE, joint_stream
    from pipeline.recording.reader import Recording

    rec = Recording(path=BUNDLED["delta-tracker"])
    rec.messages.raw[JOINT_STATE] = [json.dumps(b).encode() for b in bodies]
    try:
        joint_stream(rec)
    except RobocalError:
        pass
    except (TypeError, ValueError, OverflowError, KeyError, IndexError, AttributeError):
        try:
            first_schema_error(rec, JOINT_STATE)
        except RobocalError:
            pass


_PB = None


def _valid_batch() -> bytes:
    global _PB
    if _PB is None:
        import numpy as np

        from pipeline.recording import joint_state_batch as JSB
        _PB = JSB.encode(1_700_000_000_000_000_000 + np.arange(4), np.ones((4, 3)), ["a", "b", "c"], np.arange(4))
    return _PB


@settings(max_examples=300, deadline=None)
@given(bodies=st.lists(st.binary(max_size=120) | st.builds(
    lambda cut, flips: bytes(b ^ f for b, f in zip(_valid_batch()[:cut], flips + [0] * cut)),
    st.integers(0, 200), st.lists(st.integers(0, 255), max_size=40)), min_size=1, max_size=4))
def test_protobuf_stream_decoder_fails_only_with_a_named_record(bodies):
    """Any bytes on a protobuf encoder stream: a stream, or a one-line error naming the record."""
    from pipeline.ingest.streams import JOINT_STATE, joint_stream
    from pipeline.recording.reader import Recording

    rec = Recording(path=BUNDLED["delta-tracker"])
    rec.encodings[JOINT_STATE] = "protobuf"
    rec.messages.raw[JOINT_STATE] = list(bodies)
    try:
        s = joint_stream(rec)
    except RobocalError as e:
        assert "\n" not in str(e) and f"channel {JOINT_STATE}: record " in str(e)
        return
    assert s.q.shape == (s.t_ns.size, len(s.names)) and s.t_ns.size == s.message_index.size


@settings(max_examples=100, deadline=None)
@given(declared=st.integers(0, 1 << 40), payload=st.binary(max_size=64), comp=st.sampled_from(framing.COMPRESSIONS))
def test_decompression_never_exceeds_the_declared_size_or_limits(declared, payload, comp):
    import zstandard
    data = zstandard.ZstdCompressor().compress(payload * 1000) if comp == "zstd" else payload
    head = framing.ChunkHead(declared, 0, comp, 0, len(data))
    limits = framing.ReadLimits(max_chunk_bytes=1 << 20)
    try:
        out = framing.decompress_chunk(data, head, limits, 0)
    except framing.Damaged:
        return
    assert len(out) == declared <= limits.max_chunk_bytes
