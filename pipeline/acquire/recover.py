"""`robocal recover`: rewrite every complete record of a cut-short MCAP file into a valid one.

A recording whose writer was killed ends in the middle of a record (or has no summary and
footer).  The streaming reader (`mcap.stream_reader.StreamReader`, CRCs checked) yields every
complete record before the damage; those are written again — schemas, channels, messages
with their log/publish times and sequence numbers, metadata — by `mcap.writer.Writer`, which
adds the indexes, summary and footer.
"""

from __future__ import annotations

import json
from pathlib import Path

from mcap.records import Channel, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from pipeline import __version__
from pipeline.errors import RobocalError
from pipeline.recording.output import ACQUIRED, check_output, claim_output
from pipeline.recording.reader import MAGIC

META_RECOVERY = "robocal.recovery"


def recover(src: str | Path, dst: str | Path, force: bool | None = False) -> dict:
    """Copy the complete records of `src` into a new, well-formed MCAP file `dst` (an existing recording
    there only with `force`, kept as ``dst.bak``; `pipeline.recording.output`).  A recovered acquisition
    stays marked as one: its header's library keeps ``acquire``."""
    src, dst = Path(src), Path(dst)
    if not src.is_file():
        raise RobocalError(f"{src}: no such file")
    if src.resolve() == dst.resolve():
        raise RobocalError(f"{dst}: recover writes a new file; choose another output path")
    check_output(dst, force=force)
    with open(src, "rb") as f:
        if f.read(len(MAGIC)) != MAGIC:
            raise RobocalError(f"{src}: not an MCAP file (bad magic bytes)")
        f.seek(0)
        size = src.stat().st_size
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        stats = {"source": str(src), "source_bytes": size, "messages": 0, "metadata": 0, "channels": 0,
                 "complete_source": False, "damage": ""}
        claim_output(dst, force=force)
        with open(dst, "wb") as out:
            w = Writer(out, compression=CompressionType.ZSTD)
            profile = "robocal"
            started = False
            new_schema: dict[int, int] = {}
            new_channel: dict[int, int] = {}
            pending_meta: list[Metadata] = []
            try:
                for r in StreamReader(f, validate_crcs=True).records:
                    if isinstance(r, Header):
                        profile = r.profile
                        w.start(profile=profile, library=f"robocal/{__version__} recover"
                                + (f" {ACQUIRED}" if ACQUIRED in r.library.split() else ""))
                        started = True
                        for m in pending_meta:
                            w.add_metadata(m.name, m.metadata)
                    elif isinstance(r, Schema):
                        schemas[r.id] = r
                    elif isinstance(r, Channel):
                        channels[r.id] = r
                    elif isinstance(r, Message):
                        cid = new_channel.get(r.channel_id)
                        if cid is None:
                            ch = channels[r.channel_id]
                            sid = 0
                            if ch.schema_id:
                                if ch.schema_id not in new_schema:
                                    s = schemas[ch.schema_id]
                                    new_schema[ch.schema_id] = w.register_schema(s.name, s.encoding, s.data)
                                sid = new_schema[ch.schema_id]
                            cid = new_channel[r.channel_id] = w.register_channel(
                                ch.topic, ch.message_encoding, sid, dict(ch.metadata))
                            stats["channels"] += 1
                        w.add_message(cid, r.log_time, r.data, r.publish_time, r.sequence)
                        stats["messages"] += 1
                    elif isinstance(r, Metadata):
                        if started:
                            w.add_metadata(r.name, dict(r.metadata))
                        else:
                            pending_meta.append(r)
                        stats["metadata"] += 1
                    elif isinstance(r, Footer):
                        stats["complete_source"] = True
            except Exception as e:  # the mcap library raises several types on damaged input
                stats["damage"] = f"{type(e).__name__}: {e}"
            if not started:
                w.start(profile=profile, library=f"robocal/{__version__} recover")
            w.add_metadata(META_RECOVERY, {"json": json.dumps(stats, separators=(",", ":"))})
            w.finish()
    return stats
