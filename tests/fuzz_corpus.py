"""A seeded mutation corpus over the bundled recordings and the classification of what
robocal does with each file: used by tests/test_fuzz.py (bounded, in-process) and
benchmarks/bench_fuzz.py (full size, each case a `robocal run` process).

Classes: bit flips, truncation, corrupt chunks (garbage, emptied or unknown compression, broken
length), decompression bombs (zstd, lz4), altered schemas and message encodings, altered JSON
(deep nesting, wrong types, out-of-range numbers, NaN, not an object, cut short), altered metadata
(non-finite or absurd model numbers, swapped limits, `system` not a string, duplicate records,
not an object, fixture without faces), hostile topics (NUL, 300 bytes, colliding names) and damaged
protobuf encoder streams (the source upgraded to protobuf, then one message cut, holding an unknown
field, a wrong wire type, NaN, too few positions, or empty; or the registered FileDescriptorSet
garbage or of another type).
"""

from __future__ import annotations

import functools
import json
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hostile_support import BUNDLED, bit_flips, bomb, chunk_offsets, rebuild, replace_chunk
from google.protobuf.descriptor_pb2 import FileDescriptorSet

from pipeline.recording import joint_state_batch as JSB
from pipeline.recording.schemas import META_CAMPAIGN, META_FIXTURE, META_ROBOT

CLASSES = ("bitflip", "truncate", "chunk", "bomb", "schema", "json", "metadata", "topic", "protobuf")
OUTCOMES = ("ok", "warned", "error", "traceback", "hang", "memory", "silent-loss")


@dataclass(frozen=True)
class Case:
    cls: str
    name: str
    source: str  # bundled recording name
    make: Callable[[Path], Path]  # writes the mutated file into a folder, returns its path


@functools.cache
def _bytes(source: str) -> bytes:
    return BUNDLED[source].read_bytes()


@functools.cache
def _bomb_chunk(kind: str) -> Callable:
    """A cached bomb edit (1 GiB of zeros; compressing it once costs ~1 s)."""
    edit = bomb(kind, 1 << 30)
    cache: dict = {}

    def cached(c):
        if "data" not in cache:
            cache["data"] = edit(c)
        out = cache["data"]
        out.message_start_time, out.message_end_time = c.message_start_time, c.message_end_time
        return out
    return cached


def _write(name: str, data: bytes) -> Callable[[Path], Path]:
    def make(d: Path) -> Path:
        p = d / name
        p.write_bytes(data)
        return p
    return make


def _lazy(name: str, fn: Callable[[], bytes]) -> Callable[[Path], Path]:
    def make(d: Path) -> Path:
        p = d / name
        p.write_bytes(fn())
        return p
    return make


def _rebuild(name: str, source: str, **kw) -> Callable[[Path], Path]:
    def make(d: Path) -> Path:
        return rebuild(BUNDLED[source], d / name, **kw)
    return make


JSON_EDITS: dict[str, Callable[[dict, np.random.Generator], bytes]] = {
    "deep": lambda m, r: b'{"a":' * 3000 + b"1" + b"}" * 3000,
    "not-object": lambda m, r: b"[1, 2, 3]",
    "cut": lambda m, r: json.dumps(m).encode()[: max(1, len(json.dumps(m)) // 2)],
    "nan": lambda m, r: json.dumps({**m, "joint_positions": [float("nan")] * 3}).encode(),
    "huge-int": lambda m, r: json.dumps({**m, "timestamp_ns": 2 ** 70}).encode(),
    "1e400": lambda m, r: json.dumps({**m, "timestamp_ns": 0}).replace('"timestamp_ns": 0', '"timestamp_ns": 1e400').encode(),
    "wrong-type": lambda m, r: json.dumps({**m, r.choice(sorted(m)): {"x": [None]}}).encode(),
    "drop-field": lambda m, r: json.dumps({k: v for k, v in m.items() if k != r.choice(sorted(m))}).encode(),
    "string-number": lambda m, r: json.dumps({**m, "timestamps_ns" if "timestamps_ns" in m else "timestamp_ns": "12"}).encode(),
    "not-utf8": lambda m, r: b'{"timestamp_ns": "\xff\xfe"}',
}

def _pb_edit(fn: Callable) -> Callable[[bytes, np.random.Generator], bytes]:
    def edit(body: bytes, rng: np.random.Generator) -> bytes:
        m = JSB.JointStateBatch.FromString(body)
        fn(m, rng)
        return m.SerializeToString()
    return edit


def _other_type_fds() -> bytes:
    fd = JSB.file_descriptor()
    fd.message_type[0].field[3].type = fd.message_type[0].field[3].TYPE_FLOAT
    return FileDescriptorSet(file=[fd]).SerializeToString()


# edits of one protobuf stream message (body, rng) -> body, or of the stream's registration
PROTO_EDITS: dict[str, tuple[Callable | None, Callable[[np.random.Generator], dict] | None]] = {
    "cut": (lambda b, r: b[: int(r.integers(1, len(b)))], None),
    "unknown-field": (lambda b, r: b + b"\x38\x01", None),
    "fds-garbage": (None, lambda r: {"schema_data": r.integers(0, 256, 40, dtype=np.uint8).tobytes()}),
    "nan": (_pb_edit(lambda m, r: m.positions.__setitem__(int(r.integers(len(m.positions))), float("nan"))), None),
    "count": (_pb_edit(lambda m, r: m.positions.__delitem__(-1)), None),
    "fds-other-type": (None, lambda r: {"schema_data": _other_type_fds()}),
    "wire-type": (lambda b, r: b"\x19" + b"\x00" * 8 + b, None),  # field 3 (int64) as a fixed64
    "empty": (lambda b, r: b"", None),
}


@functools.cache
def _pb_source(source: str) -> Path:
    """The bundled recording `source` with its encoder stream upgraded to protobuf (once per process)."""
    from pipeline.recording.upgrade import upgrade

    out = Path(tempfile.mkdtemp(prefix="robocal-fuzz-pb-")) / f"{source}-pb.mcap"
    upgrade(BUNDLED[source], out)
    return out


def _protobuf_case(name: str, source: str, edit: str, index: int, rng: np.random.Generator) -> Callable[[Path], Path]:
    msg_edit, channel_edit = PROTO_EDITS[edit]
    spec = channel_edit(rng) if channel_edit else {}

    def make(d: Path) -> Path:
        return rebuild(_pb_source(source), d / name,
                       msg=(lambda t, i, b: msg_edit(b, rng) if (t == "/robot/joint_state" and i == index) else b)
                       if msg_edit else None,
                       channel=lambda t: spec if t == "/robot/joint_state" else {})
    return make


META_EDITS: dict[str, Callable[[dict], list]] = {
    "model-nan": lambda md: list({**md, META_ROBOT: _first_number(md[META_ROBOT], float("nan"))}.items()),
    "model-inf": lambda md: list({**md, META_ROBOT: _first_number(md[META_ROBOT], float("inf"))}.items()),
    "model-1e308": lambda md: list({**md, META_ROBOT: _first_number(md[META_ROBOT], 1e308)}.items()),
    "system-list": lambda md: list({**md, META_CAMPAIGN: {**md.get(META_CAMPAIGN, {}), "system": [1]}}.items()),
    "duplicate-model": lambda md: list(md.items()) + [(META_ROBOT, md[META_ROBOT])],
    "model-not-object": lambda md: list({**md, META_ROBOT: "[1, 2]"}.items()),
    "model-bad-json": lambda md: list({**md, META_ROBOT: "{"}.items()),
    "no-model": lambda md: [(k, v) for k, v in md.items() if k != META_ROBOT],
    "fixture-no-faces": lambda md: list({**md, META_FIXTURE: {k: v for k, v in md.get(META_FIXTURE, {}).items()
                                                              if k != "faces"}}.items()),
    "limits-swapped": lambda md: list({**md, META_ROBOT: _swap_limits(md[META_ROBOT])}.items()),
}


def _first_number(doc: dict, value: float) -> dict:
    """A copy of the model with its first numeric field (depth first) set to `value`."""
    doc = json.loads(json.dumps(doc))
    stack = [doc]
    while stack:
        o = stack.pop()
        items = o.items() if isinstance(o, dict) else enumerate(o) if isinstance(o, list) else []
        for k, v in list(items):
            if isinstance(v, (int, float)) and not isinstance(v, bool) and k not in ("lower", "upper"):
                o[k] = value
                return doc
            if isinstance(v, (dict, list)):
                stack.append(v)
    return doc


def _swap_limits(doc: dict) -> dict:
    doc = json.loads(json.dumps(doc))
    if "lower" in doc and "upper" in doc:
        doc["lower"], doc["upper"] = doc["upper"], doc["lower"]
    for j in doc.get("joints", []):
        if "lower" in j and "upper" in j:
            j["lower"], j["upper"] = j["upper"], j["lower"]
    return doc


def _emptied(c):
    c.compression = ""
    return c


def _unknown(c):
    c.compression = "brotli"
    return c


def cases(seed: int, per_class: int, sources: tuple[str, ...] = ("delta-tracker", "scorbot-scanner")) -> Iterator[Case]:
    """`per_class` cases of every class over `sources`, reproducible from `seed`."""
    rng = np.random.default_rng(seed)
    for k in range(per_class):
        src = sources[k % len(sources)]
        buf = _bytes(src)
        offs = chunk_offsets(buf)
        tag = f"{src}-{k}"
        yield Case("bitflip", f"bitflip-{tag}", src, _write(f"bitflip-{tag}.mcap", bit_flips(buf, rng, int(rng.integers(1, 65)))))
        cut = int(rng.integers(9, len(buf)))
        yield Case("truncate", f"truncate-{tag}@{cut}", src, _write(f"truncate-{tag}.mcap", buf[:cut]))
        c = int(rng.integers(len(offs)))
        how = ("garbage", "emptied", "unknown", "length")[k % 4]
        if how == "garbage":
            b = bytearray(buf)
            a = offs[c] + 9 + int(rng.integers(0, 200))
            b[a:a + 64] = rng.integers(0, 256, 64, dtype=np.uint8).tobytes()
            data = bytes(b)
        elif how == "length":
            b = bytearray(buf)
            b[offs[c] + 1:offs[c] + 9] = int(rng.integers(0, 1 << 62)).to_bytes(8, "little")
            data = bytes(b)
        else:
            data = replace_chunk(buf, c, _emptied if how == "emptied" else _unknown)
        yield Case("chunk", f"chunk-{how}-{tag}", src, _write(f"chunk-{tag}.mcap", data))
        kind = ("zstd", "lz4")[k % 2]
        yield Case("bomb", f"bomb-{kind}-{tag}", src,
                   _lazy(f"bomb-{tag}.mcap", lambda buf=buf, c=c, kind=kind: replace_chunk(buf, c, _bomb_chunk(kind))))
        spec = ({"schema_data": rng.integers(0, 256, 40, dtype=np.uint8).tobytes()}, {"message_encoding": "cbor"},
                {"schema_name": "robocal.Other"}, {"schema_encoding": "protobuf"})[k % 4]
        topic = "/robot/joint_state" if k % 3 == 0 else None
        yield Case("schema", f"schema-{'-'.join(spec)}-{tag}", src,
                   _rebuild(f"schema-{tag}.mcap", src, channel=lambda t, spec=spec, topic=topic:
                            spec if (t == topic if topic else t != "/robot/joint_state") else {}))
        edit = list(JSON_EDITS)[k % len(JSON_EDITS)]
        jtopic = "/robot/joint_state" if k % 2 else None
        idx = int(rng.integers(0, 5))
        sub = np.random.default_rng([seed, k])
        yield Case("json", f"json-{edit}-{jtopic or 'measurement'}-{tag}", src,
                   _rebuild(f"json-{tag}.mcap", src, msg=lambda t, i, d, e=edit, jt=jtopic, idx=idx, sub=sub:
                            JSON_EDITS[e](json.loads(d), sub) if i == idx and ((t == jt) if jt else
                                                                               t != "/robot/joint_state") else d))
        medit = list(META_EDITS)[k % len(META_EDITS)]
        yield Case("metadata", f"metadata-{medit}-{tag}", src, _rebuild(f"metadata-{tag}.mcap", src, meta=META_EDITS[medit]))
        t0 = 1_700_000_000_000_000_000
        topics = (["/evil\x00name"], ["/" + "x" * 300], ["/tracker_point", "/tracker/point_"],
                  ["/encoder", "/messages", "/measurements"])[k % 4]
        yield Case("topic", f"topic-{k % 4}-{tag}", src,
                   _rebuild(f"topic-{tag}.mcap", src, extra=[(t, t0 + i, b'{"timestamp_ns":1}') for i, t in enumerate(topics)]))
        pedit = list(PROTO_EDITS)[k % len(PROTO_EDITS)]
        prng = np.random.default_rng([seed, k, 17])  # its own stream: the other classes' cases are as before
        yield Case("protobuf", f"protobuf-{pedit}-{tag}", src,
                   _protobuf_case(f"protobuf-{tag}.mcap", src, pedit, int(prng.integers(0, 5)), prng))


def message_count(path: Path) -> int:
    from pipeline.recording.reader import read_recording

    return sum(map(len, read_recording(path).messages.raw.values()))


def workdir() -> Path:
    return Path(tempfile.mkdtemp(prefix="robocal-fuzz-"))


class _Hang(Exception):
    pass


def classify_inprocess(path: Path, run_dir: Path, original: int, stages=("ingest", "validate"),
                       timeout_s: float = 30.0) -> tuple[str, str]:
    """(outcome, detail) of `run_pipeline` on `path` in this process (see OUTCOMES): an error must be
    a `RobocalError` of one line naming the file; a success that lost messages must say so in its
    warnings and not have status pass."""
    import signal

    from pipeline.errors import RobocalError
    from pipeline.stages.runner import run_pipeline

    def alarm(*_):
        raise _Hang()

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout_s)
    try:
        run_pipeline(path, run_dir, stages=list(stages))
    except RobocalError as e:
        msg = str(e)
        named = str(path) in msg or str(path.resolve()) in msg
        return ("error" if named and "\n" not in msg else "traceback"), msg[:300]
    except _Hang:
        return "hang", f"over {timeout_s} s"
    except MemoryError:
        return "memory", "MemoryError"
    except Exception as e:  # noqa: BLE001 — exactly what the classification is about
        import traceback
        return "traceback", "".join(traceback.format_exception(e))[-1500:]
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    res = json.loads((run_dir / "results.json").read_text())
    got = message_count(path)
    if got >= original:
        return "ok", res["summary"]["status"]
    if res["summary"]["status"] != "pass" and res["warnings"]:
        return "warned", f"{original - got} lost: {res['warnings'][0][:200]}"
    return "silent-loss", f"{original - got} messages lost; status {res['summary']['status']}; {res['warnings'][:1]}"
