"""Rebuild a valid MCAP file from a truncated one.

A recorder that dies without closing (SIGKILL, a crash, a power cut) leaves a
file with no summary and no footer, often ending in the middle of a record.
Most tools refuse it or need the summary to seek. :func:`recover` reads the
file front to back with mcap's streaming reader (no seeking, no summary
needed), stops at the first record that is incomplete or corrupt (short read,
bad length, chunk that does not decompress or fails its CRC), and writes every
complete message before it, with its schema and channel, to a new valid MCAP.

What is lost:

* the chunk the writer was filling: it lived in the writer's memory and never
  reached the file (for :class:`~vmas_ros.record.mcap_recorder.McapRecorder`,
  up to ``chunk_size`` bytes of messages, i.e. the last ``chunk_size / message
  size`` messages);
* a chunk that was only partly written when the process died, and anything
  after the first corrupt record, even if later records are intact;
* the summary section, which is rebuilt (statistics, indexes) for what remains.

Chunk message indexes are not needed: messages are read from the chunks.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Dict, Optional, Union

from mcap.exceptions import EndOfFile
from mcap.records import Attachment, Channel, Chunk, DataEnd, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import MCAP0_MAGIC as _MAGIC
from mcap.writer import Writer

__all__ = ["recover"]


class _Truncated(EndOfFile):
    """The file ended inside a record."""


class _StrictInput:
    """A read-only file that refuses short reads: mcap's reader silently accepts a
    record cut off by the end of the file, this raises instead. Counts bytes read."""

    def __init__(self, f) -> None:
        self._f = f
        self.pos = 0

    def read(self, n: int = -1) -> bytes:
        data = self._f.read(n)
        if n is not None and n >= 0 and len(data) < n:
            raise _Truncated(f"file ends at byte {self.pos + len(data)} inside a record needing {n} bytes")
        self.pos += len(data)
        return data


def recover(
    path_in: Union[str, os.PathLike],
    path_out: Union[str, os.PathLike],
    compression: str = "zstd",
    chunk_size: int = 1024 * 1024,
) -> Dict[str, object]:
    """Copy every complete message of the (possibly truncated) MCAP ``path_in`` to a
    new, finished MCAP ``path_out``; schemas, channels (with their metadata),
    metadata and attachments before the damage come along, the header's profile
    too. Returns a report::

        {"messages": recovered messages, "topics": {topic: count},
         "chunks": complete chunks read, "schemas": n, "channels": n,
         "complete": True if the input had its data section end (nothing lost),
         "error": why reading stopped (None when complete),
         "bytes_used": bytes of the input read up to the last good record,
         "bytes_total": size of the input}
    """
    from vmas_ros.record.mcap_recorder import _COMPRESSIONS, DEFAULT_COMPRESSION

    if compression == "zstd" and DEFAULT_COMPRESSION != "zstd":
        compression = "none"
    path_in, path_out = Path(path_in), Path(path_out)
    if path_in.resolve() == path_out.resolve():
        raise ValueError("recover() writes a new file: path_out must differ from path_in")
    report: Dict[str, object] = {
        "messages": 0, "topics": {}, "chunks": 0, "schemas": 0, "channels": 0,
        "complete": False, "error": None, "bytes_used": 0, "bytes_total": path_in.stat().st_size,
    }
    schema_ids: Dict[int, int] = {}  # input id -> output id
    channel_ids: Dict[int, int] = {}
    topics: Dict[int, str] = {}
    header: Optional[Header] = None
    writer: Optional[Writer] = None

    def start(profile: str, library: str) -> Writer:
        w = Writer(str(path_out), chunk_size=chunk_size, compression=_COMPRESSIONS[compression])
        w.start(profile=profile, library=library)
        return w

    def take(record) -> None:
        if isinstance(record, Schema):
            if record.id not in schema_ids:
                schema_ids[record.id] = writer.register_schema(record.name, record.encoding, record.data)
        elif isinstance(record, Channel):
            if record.id not in channel_ids:
                if record.schema_id != 0 and record.schema_id not in schema_ids:
                    raise ValueError(f"channel {record.topic} refers to unknown schema {record.schema_id}")
                channel_ids[record.id] = writer.register_channel(
                    record.topic, record.message_encoding, schema_ids.get(record.schema_id, 0), dict(record.metadata)
                )
                topics[record.id] = record.topic
        elif isinstance(record, Message):
            if record.channel_id not in channel_ids:
                raise ValueError(f"message on unknown channel {record.channel_id}")
            writer.add_message(
                channel_ids[record.channel_id], log_time=record.log_time, data=record.data,
                publish_time=record.publish_time, sequence=record.sequence,
            )
            report["messages"] += 1
            counts = report["topics"]
            topic = topics[record.channel_id]
            counts[topic] = counts.get(topic, 0) + 1
        elif isinstance(record, Metadata):
            writer.add_metadata(record.name, dict(record.metadata))
        elif isinstance(record, Attachment):
            writer.add_attachment(record.create_time, record.log_time, record.name, record.media_type, record.data)

    with open(path_in, "rb") as raw:
        magic = raw.read(len(_MAGIC))
        if not _MAGIC.startswith(magic):  # empty or a cut-off magic: nothing to recover
            raise ValueError(f"{path_in} is not an MCAP file (it does not start with the MCAP magic)")
        raw.seek(0)
        source = _StrictInput(raw)
        reader = StreamReader(source, emit_chunks=True, validate_crcs=True)
        records = reader.records
        try:
            while True:
                try:
                    record = next(records)
                except StopIteration:
                    break
                if isinstance(record, Header):
                    if writer is not None:
                        raise ValueError("a second header record")
                    header = record
                    writer = start(record.profile, record.library)
                    report["bytes_used"] = source.pos
                    continue
                if writer is None:  # tolerate nothing before the header
                    raise ValueError(f"expected the header record first, found {type(record).__name__}")
                if isinstance(record, Chunk):
                    inner = breakup_chunk(record, validate_crc=True)  # all or nothing
                    for item in inner:
                        take(item)
                    report["chunks"] += 1
                elif isinstance(record, (DataEnd, Footer)):
                    report["complete"] = True
                    report["bytes_used"] = source.pos
                    break  # the summary repeats what the data section had
                else:
                    take(record)
                report["bytes_used"] = source.pos
        except Exception as error:  # the first damaged record ends the recovery
            report["error"] = f"{type(error).__name__}: {error}" if str(error) else type(error).__name__
        finally:
            if writer is None:  # not even a header: still write a valid (empty) file
                writer = start("ros2" if header is None else header.profile, "vmas_ros.record.recover")
            writer.finish()
    report["schemas"] = len(schema_ids)
    report["channels"] = len(channel_ids)
    return report
