"""Low-level helpers of :mod:`vmas_ros.record.mcap_recorder`: rosbag2 QoS
metadata, split file names, ``/tf`` CDR serialisation without tf2_msgs, the
unbuffered output file and its MCAP writer, the signals deferred during a
write and topic-name normalisation. Public names are re-exported by
:mod:`vmas_ros.record.mcap_recorder`.
"""
from __future__ import annotations

import errno
import os
import re
import signal
import struct
import threading
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Union

from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

__all__ = ["TF_MESSAGE_TYPE", "qos_profile_yaml", "serialize_tf_message", "split_path"]

#: the type name the node uses for /tf (tf2_msgs has no PyPI wheel: see write_raw)
TF_MESSAGE_TYPE = "tf2_msgs/msg/TFMessage"

#: bytes of a Message record besides its data: opcode, length, channel id,
#: sequence, log time, publish time
_MESSAGE_RECORD_OVERHEAD = 1 + 8 + 2 + 4 + 8 + 8
#: a Chunk record besides its records: opcode, length, start/end time,
#: uncompressed size and CRC, compression name (<= 4 chars), records length
_CHUNK_OVERHEAD = 1 + 8 + 8 + 8 + 8 + 4 + 4 + 4 + 8
#: a MessageIndex record per channel of a chunk, and an entry per message
_INDEX_OVERHEAD = 1 + 8 + 2 + 4
_INDEX_ENTRY = 8 + 8

_QOS = ("reliable", "best_effort")

# rmw's "infinite" duration (INT64_MAX ns) as rosbag2 writes it
_INFINITE = "    sec: 9223372036\n    nsec: 854775807\n"


def qos_profile_yaml(reliability: str = "reliable", depth: int = 10) -> str:
    """``offered_qos_profiles`` YAML as rosbag2 (Jazzy, metadata version 9) writes it
    for one publisher with keep_last(``depth``), volatile, ``reliability``."""
    if reliability not in _QOS:
        raise ValueError(f"qos must be 'reliable' or 'best_effort', not {reliability!r}")
    return (
        "- history: keep_last\n"
        f"  depth: {int(depth)}\n"
        f"  reliability: {reliability}\n"
        "  durability: volatile\n"
        f"  deadline:\n{_INFINITE}"
        f"  lifespan:\n{_INFINITE}"
        "  liveliness: automatic\n"
        f"  liveliness_lease_duration:\n{_INFINITE}"
        "  avoid_ros_namespace_conventions: false"
    )


def split_path(path: Union[str, os.PathLike], index: int) -> Path:
    """The path of file ``index`` of a recording to ``path``: ``path`` itself for
    0, else ``<stem>_<index>.mcap`` in the same directory."""
    path = Path(path)
    if index == 0:
        return path
    stem = path.name[: -len(".mcap")] if path.name.endswith(".mcap") else path.name
    return path.with_name(f"{stem}_{index}.mcap")


def _describe(path: Path) -> str:
    """What sits at ``path``, for errors: a symlink and its target, a directory or a file."""
    if path.is_symlink():
        return f"a symlink to {os.readlink(path)!r}"
    return "a directory" if path.is_dir() else "a file"


def refuse_symlink(path: Path) -> None:
    """Raise FileExistsError if ``path`` is a symlink, dangling or not: writing through it would
    put the recording wherever it points (the user named ``path``, not its target)."""
    if path.is_symlink():
        raise FileExistsError(f"{path} is {_describe(path)}; the recorder does not write through symlinks, "
                              "give the real path")


def _stale_split_files(path: Path) -> List[Path]:
    stem = path.name[: -len(".mcap")] if path.name.endswith(".mcap") else path.name
    pattern = re.compile(re.escape(stem) + r"_\d+\.mcap$")
    if not path.parent.is_dir():
        return []
    return sorted(p for p in path.parent.iterdir() if pattern.fullmatch(p.name))


# ---------------------------------------------------------------- TF messages
_CDR_LE = b"\x00\x01\x00\x00"  # encapsulation header: plain CDR, little endian
_TRANSFORM_BYTES = 7 * 8  # geometry_msgs/Transform: Vector3 + Quaternion, float64 each


def _pad(buf: bytearray, alignment: int) -> None:
    """Zero-pad ``buf`` (header + payload) so the payload length is a multiple of ``alignment``."""
    buf.extend(b"\x00" * (-(len(buf) - 4) % alignment))


def serialize_tf_message(transforms: Sequence) -> bytes:
    """CDR bytes of a ``tf2_msgs/msg/TFMessage`` holding ``transforms``.

    ``transforms`` are ``geometry_msgs.msg.TransformStamped`` instances. tf2_msgs
    has no PyPI wheel, so rclpy cannot build a TFMessage; its CDR is a uint32
    element count followed by the elements, which this function takes from
    rclpy's serialisation of each TransformStamped. CDR aligns every primitive
    relative to the start of the payload (after the 4-byte encapsulation
    header), so an element is not always a verbatim copy of its standalone
    bytes: the 4-byte aligned part (stamp, frame ids) is copied after padding
    to 4, the float64 part (the transform) after padding to 8 of the combined
    payload. Pass the result to :meth:`McapRecorder.write_raw` with
    :data:`TF_MESSAGE_TYPE`.
    """
    from geometry_msgs.msg import TransformStamped
    from rclpy.serialization import serialize_message

    out = bytearray(_CDR_LE)
    out += struct.pack("<I", len(transforms))
    for k, tf in enumerate(transforms):
        if not isinstance(tf, TransformStamped):
            raise TypeError(f"transforms[{k}] is {type(tf).__name__}, not geometry_msgs/TransformStamped")
        raw = serialize_message(tf)
        if raw[:4] != _CDR_LE:
            raise ValueError(f"unexpected CDR encapsulation {raw[:4].hex()} from rclpy (expected little endian)")
        body = raw[4:]
        # stamp (int32 sec, uint32 nanosec), then two strings (uint32 length incl. NUL + bytes);
        # rclpy leaves padding bytes uninitialised, so rebuild the padding as zeros
        _pad(out, 4)
        out += body[:8]
        pos = 8
        for _ in range(2):
            pos += -pos % 4
            (length,) = struct.unpack_from("<I", body, pos)
            _pad(out, 4)
            out += body[pos:pos + 4 + length]
            pos += 4 + length
        transform = body[pos + (-pos % 8):]
        if len(transform) != _TRANSFORM_BYTES:
            raise ValueError(f"unexpected TransformStamped layout from rclpy ({len(body)} bytes)")
        _pad(out, 8)
        out += transform
    return bytes(out)


# ------------------------------------------------------------------ the files
class _UnbufferedFile:
    """The output stream handed to ``mcap.writer.Writer``: each write goes to the OS
    at once (so a finished chunk survives a SIGKILL) and the position is counted
    here. Not a RawIOBase on purpose: Writer would wrap that in a BufferedWriter."""

    def __init__(self, path: Path) -> None:
        # a new file only: O_EXCL refuses anything already there, and with O_CREAT a symlink
        # too, dangling or not (it would put the bag wherever it points)
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
        try:
            self._fd = os.open(path, flags, 0o644)
        except FileExistsError:
            raise FileExistsError(f"{path} appeared while recording ({_describe(path)}); "
                                  "the recorder writes only files it creates") from None
        self._pos = 0

    def write(self, data) -> int:
        view = memoryview(data).cast("B")
        while view.nbytes:
            n = os.write(self._fd, view)
            self._pos += n
            view = view[n:]
        return len(data)

    def tell(self) -> int:
        return self._pos

    def flush(self) -> None:
        pass

    def check_linked(self, path: Path) -> None:
        """Raise FileNotFoundError if the open file was deleted (or its folder removed) meanwhile:
        writes to it still succeed, but nothing of them would remain."""
        if self._fd >= 0 and os.fstat(self._fd).st_nlink == 0:
            raise FileNotFoundError(errno.ENOENT, "the file was deleted while recording", str(path))

    def close(self) -> None:
        if self._fd >= 0:
            fd, self._fd = self._fd, -1
            os.close(fd)


class _OpenFile:
    """One MCAP file of the recording: its writer and what it already registered."""

    def __init__(self, path: Path, chunk_size: int, compression: CompressionType) -> None:
        self.path = path
        self.stream = _UnbufferedFile(path)
        self.writer = Writer(self.stream, chunk_size=chunk_size, compression=compression)
        self.writer.start(profile="ros2", library=f"vmas_ros.record; {LIBRARY_IDENTIFIER}")
        self.schemas: Dict[str, int] = {}
        self.channels: Dict[str, int] = {}
        self.messages = 0
        self.flushed_messages = 0  # messages in chunks already handed to the OS: what a failure keeps
        self.first_log_time: Optional[int] = None
        # the open chunk, as the writer will write it out: records (uncompressed),
        # messages and channels (for the message indexes that follow the chunk)
        self._chunk_records = 0
        self._chunk_messages = 0
        self._chunk_channels: set = set()

    def size(self) -> int:
        """Bytes written so far plus what the open chunk will add (uncompressed)."""
        if not self._chunk_records:
            return self.stream.tell()
        return (
            self.stream.tell() + _CHUNK_OVERHEAD + self._chunk_records
            + _INDEX_ENTRY * self._chunk_messages + _INDEX_OVERHEAD * len(self._chunk_channels)
        )

    def _track(self, before: int, record_bytes: int, channel_id: Optional[int] = None) -> None:
        if self.stream.tell() != before:  # the writer just wrote out the chunk
            self._reset_chunk()
        else:
            self._chunk_records += record_bytes
            if channel_id is not None:
                self._chunk_messages += 1
                self._chunk_channels.add(channel_id)

    def _reset_chunk(self) -> None:
        self.flushed_messages = self.messages
        self._chunk_records = self._chunk_messages = 0
        self._chunk_channels.clear()

    def channel(self, topic: str, type_name: str, definition: str, metadata: Dict[str, str]) -> int:
        channel_id = self.channels.get(topic)
        if channel_id is None:
            schema_id = self.schemas.get(type_name)
            if schema_id is None:
                data = definition.encode()
                before = self.stream.tell()
                schema_id = self.schemas[type_name] = self.writer.register_schema(type_name, "ros2msg", data)
                self._track(before, 9 + 2 + 4 + len(type_name) + 4 + len("ros2msg") + 4 + len(data))
            before = self.stream.tell()
            channel_id = self.channels[topic] = self.writer.register_channel(topic, "cdr", schema_id, metadata)
            meta = 4 + sum(8 + len(k.encode()) + len(v.encode()) for k, v in metadata.items())
            self._track(before, 9 + 2 + 2 + 4 + len(topic.encode()) + 4 + len("cdr") + meta)
        return channel_id

    def add(self, channel_id: int, data: bytes, log_time: int, sequence: int) -> None:
        before = self.stream.tell()
        self.writer.add_message(channel_id, log_time=log_time, data=data, publish_time=log_time, sequence=sequence)
        if self.first_log_time is None:
            self.first_log_time = log_time
        self.messages += 1
        self._track(before, len(data) + _MESSAGE_RECORD_OVERHEAD, channel_id)

    def flush(self) -> None:
        self.writer.flush()
        self._reset_chunk()

    def close(self) -> None:
        try:
            self.stream.check_linked(self.path)
            self.writer.finish()
        finally:
            self.stream.close()

    def abandon(self) -> None:
        """Close the file without its summary (after a write error): what is on disk stays."""
        self.stream.close()


# ------------------------------------------------------------ signals, topics
_DEFERRED = frozenset({signal.SIGINT, signal.SIGTERM})
_MAIN_THREAD_ID = threading.main_thread().ident


def _absolute(topic: str) -> str:
    if not isinstance(topic, str) or not topic.strip("/"):
        raise ValueError(f"not a topic name: {topic!r}")
    return topic if topic.startswith("/") else "/" + topic
