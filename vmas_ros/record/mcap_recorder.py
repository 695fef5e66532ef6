"""A rosbag2-compatible MCAP recorder that runs inside the publishing process.

:class:`McapRecorder` writes what a node publishes straight to MCAP files of the
``ros2`` profile, as ``ros2 bag record -s mcap`` would: one Schema record per
message type (encoding ``ros2msg``, the full definition from
:mod:`vmas_ros.record.schemas`), one Channel per topic (message encoding
``cdr``, metadata ``offered_qos_profiles`` in rosbag2's YAML), CDR messages in
chunks, and on close a summary (schemas, channels, statistics, chunk and
message indexes). ``rosbags``, ``mcap-ros2-support``, Foxglove and ``ros2 bag``
read the files.

Files and folders
    A path ending in ``.mcap`` is a single file; any other path is a rosbag2
    bag folder (``NAME/NAME_0.mcap`` and ``NAME/metadata.yaml``, written at
    close); see :mod:`vmas_ros.record.rosbag2`. With ``max_bytes`` or
    ``max_duration_s`` the recording continues in a new file when the current
    one is full: ``run_1.mcap``, ``run_2.mcap``, ... beside ``run.mcap``, or
    ``NAME_1.mcap``, ... in the folder. Every file is a complete,
    independently readable MCAP. :attr:`McapRecorder.paths` lists them.

Write errors
    A full disk, a read-only or vanished folder: the first failed write ends
    the recording (:class:`RecordingFailed` says what failed, where, and how
    many messages are safe) and later writes are dropped. The files keep every
    chunk written before the failure; ``vmas-ros bag-recover`` finishes them.
    With ``on_failure`` the error goes to that callback instead of being raised
    from the write, so a node can keep running. A file deleted while open is
    noticed when it is closed (the writes themselves still succeed).

Durability
    Messages collect in an in-memory chunk (``chunk_size`` bytes, before
    compression); a full chunk goes to the operating system at once (unbuffered
    writes), so a killed process (SIGKILL, a crash) loses at most the open chunk
    and the summary; :func:`vmas_ros.record.recover.recover` rebuilds a valid
    file from the rest. :meth:`McapRecorder.flush` ends the open chunk early. A
    normal interpreter exit closes the recorder (``atexit``), and so does
    ``SystemExit`` raised from a signal handler. Nothing is ``fsync``-ed: a power
    cut can lose more.

Signals
    With ``defer_signals`` (the default) a write from the main thread defers
    SIGINT and SIGTERM while it changes the file's state, so that a
    KeyboardInterrupt or a ``sys.exit`` from a signal handler lands between two
    writes, never in the middle of one (which would leave a corrupt chunk for
    the ``atexit`` close to finish). Two things are needed for that: the main
    thread blocks both signals (``pthread_sigmask``), and Python-level handlers
    are swapped for one that only notes the signal, because a signal the kernel
    delivers to another thread (torch's, rclpy's) still makes the main thread
    run its Python handler at the next bytecode. The noted signals go to the
    original handlers as soon as the write is complete. A handler object with
    ``hold()`` and ``release()`` methods (sim_node's, from
    :mod:`vmas_ros.ros.signal_guard`) is not swapped but asked to hold the signal
    itself, which keeps a C-level handler chained in front of it (rclpy's, which
    wakes the executor) installed. That costs a little on every write;
    :meth:`McapRecorder.batch` pays it once for a group of writes.
"""
from __future__ import annotations

import atexit
import contextlib
import os
import signal
import threading
from pathlib import Path
from typing import Callable, Dict, Iterable, Iterator, List, Optional, Tuple, Union

from mcap.writer import CompressionType

from vmas_ros.record._io import (
    _DEFERRED,
    _INDEX_ENTRY,
    _INDEX_OVERHEAD,
    _MAIN_THREAD_ID,
    _MESSAGE_RECORD_OVERHEAD,
    _QOS,
    _absolute,
    _OpenFile,
    qos_profile_yaml,
)
from vmas_ros.record.claim import PathClaim
from vmas_ros.record.rosbag2 import BagFolder, bag_layout
from vmas_ros.record.schemas import message_definition, normalize_type

__all__ = ["DEFAULT_COMPRESSION", "McapRecorder", "RecordingFailed"]

try:  # what mcap needs to write (and read) zstd chunks
    import zstandard  # noqa: F401

    DEFAULT_COMPRESSION = "zstd"
except ImportError:  # pragma: no cover - depends on the installation
    DEFAULT_COMPRESSION = "none"

_COMPRESSIONS = {
    "zstd": CompressionType.ZSTD,
    "lz4": CompressionType.LZ4,
    "none": CompressionType.NONE,
    "": CompressionType.NONE,
    None: CompressionType.NONE,
}


class RecordingFailed(RuntimeError):
    """Writing the bag failed (disk full, read-only, vanished): the recording has ended.

    ``bag`` is the recording's path, ``path`` the file that failed, ``cause``
    the OSError, ``safe`` the messages in chunks known to be complete on disk
    (a chunk whose write failed after its last byte, in its index, counts
    only when recovered, so the bag may hold a chunk more),
    ``total`` the messages recorded up to the failure and ``unfinished``
    whether a file was left without its summary (``vmas-ros bag-recover``
    finishes it; for a folder it also rebuilds ``metadata.yaml``).
    """

    def __init__(self, bag: Path, path, cause: OSError, safe: int, total: int, unfinished: bool,
                 folder: bool) -> None:
        self.bag, self.path, self.cause = bag, Path(path), cause
        self.safe, self.total, self.unfinished = safe, total, unfinished
        reason = cause.strerror or str(cause) or type(cause).__name__
        text = (f"recording to {bag} failed: writing {self.path}: {reason}; "
                f"at least {safe} of {total} messages are safe")
        if unfinished or folder:
            text += f" (`vmas-ros bag-recover {bag}` makes the bag readable)"
        super().__init__(text)


# --------------------------------------------------------------- the recorder
class McapRecorder:
    """Records ROS 2 messages to rosbag2-compatible MCAP files.

    :param path: ``NAME.mcap`` (a single file and its splits) or ``NAME`` (a
        rosbag2 bag folder); see the module docstring.
    :param topics: topics to record (None: all); writes to other topics are ignored.
    :param max_bytes: start a new file before a message would grow the current
        one's data section past this many bytes (the open chunk counts
        uncompressed, so compressed files come out smaller; the summary written
        at close, a few hundred bytes plus the indexes, comes on top).
    :param max_duration_s: start a new file before a message whose log time is
        more than this many seconds after the file's first message: a file's log
        times span at most ``max_duration_s``.
    :param chunk_size: chunk size in bytes before compression; what a SIGKILL can lose.
    :param compression: ``"zstd"`` (the default when ``zstandard`` is installed),
        ``"lz4"`` or ``"none"``.
    :param overwrite: replace an existing recording at ``path`` (including its
        ``<stem>_<n>.mcap`` split files, or a bag folder's files); otherwise an
        existing recording is refused (:class:`RecordingExists`). A symlink at
        ``path`` is always refused (FileExistsError naming it and its target),
        dangling or not: the recording would land where it points. Every file
        is created new (``O_EXCL | O_NOFOLLOW``), never opened in place.
    :param defer_signals: block SIGINT/SIGTERM during a write from the main thread.
    :param on_failure: called with the :class:`RecordingFailed` of a write
        error instead of raising it (from whichever thread wrote).

    Topic names are fully qualified: a name without a leading ``/`` gets one,
    both in ``topics`` and in writes. Log times are nanoseconds and must not
    decrease over the whole recording (ValueError otherwise). Use as a context
    manager or call :meth:`close`; an unclosed recorder closes at interpreter exit.
    """

    def __init__(
        self,
        path: Union[str, os.PathLike],
        topics: Optional[Iterable[str]] = None,
        max_bytes: Optional[int] = None,
        max_duration_s: Optional[float] = None,
        chunk_size: int = 1024 * 1024,
        compression: Optional[str] = DEFAULT_COMPRESSION,
        overwrite: bool = False,
        defer_signals: bool = True,
        on_failure: Optional[Callable[[RecordingFailed], None]] = None,
    ) -> None:
        if isinstance(topics, str):
            raise TypeError("topics must be an iterable of topic names, not a single string")
        if max_bytes is not None and max_bytes <= 0:
            raise ValueError(f"max_bytes must be positive, not {max_bytes}")
        if max_duration_s is not None and not max_duration_s > 0:
            raise ValueError(f"max_duration_s must be positive, not {max_duration_s}")
        if chunk_size <= 0:
            raise ValueError(f"chunk_size must be positive, not {chunk_size}")
        if compression not in _COMPRESSIONS:
            raise ValueError(f"compression must be 'zstd', 'lz4' or 'none', not {compression!r}")
        if compression == "zstd" and DEFAULT_COMPRESSION != "zstd":
            raise ValueError("compression='zstd' needs the zstandard package (pip install zstandard)")
        self._layout = bag_layout(path)
        self._path = self._layout.bag
        self._claim = PathClaim(self._layout.path)  # before prepare: overwrite must not hit a live bag
        try:
            self._layout.prepare(overwrite)
        except BaseException:
            self._claim.release()
            raise
        self._on_failure = on_failure
        self._failure: Optional[RecordingFailed] = None
        self._finished: List[Tuple[Path, int]] = []  # files closed complete, with their message counts
        self._first_log_time: Optional[int] = None
        self._topics = None if topics is None else frozenset(_absolute(t) for t in topics)
        self._max_bytes = max_bytes
        self._max_duration_ns = None if max_duration_s is None else int(round(max_duration_s * 1e9))
        self._chunk_size = int(chunk_size)
        self._compression = _COMPRESSIONS[compression]
        self._defer = defer_signals and hasattr(signal, "pthread_sigmask")
        self._deferring = 0  # nesting depth of deferred-signal sections (main thread only)
        self._lock = threading.RLock()
        self._types: Dict[str, Tuple[str, Dict[str, str]]] = {}  # topic -> (type, channel metadata)
        self._definitions: Dict[str, str] = {}
        self._names: Dict[Tuple[str, str], Tuple[str, str]] = {}  # as written -> (topic, type) recorded
        self._counts: Dict[str, int] = {}
        self._last: Optional[Tuple[int, str]] = None  # (log time, topic) of the last message
        self._paths: List[Path] = []
        self._file: Optional[_OpenFile] = None
        self._closed = False
        # a signal between creating the file and registering the atexit close would leave a
        # header-only file nobody finishes (seen with SIGINT during sim_node's start-up)
        with self._deferred_signals():
            try:
                self._open_next()
            except BaseException:
                self._claim.release()
                raise
            atexit.register(self.close)

    # ------------------------------------------------------------- properties
    @property
    def paths(self) -> List[Path]:
        """The files of this recording so far, in order (the last one may be open)."""
        return list(self._paths)

    @property
    def message_counts(self) -> Dict[str, int]:
        """Messages recorded per topic, over all files."""
        return dict(self._counts)

    @property
    def message_count(self) -> int:
        return sum(self._counts.values())

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def bag(self) -> Path:
        """The recording's path: the ``.mcap`` file or the bag folder."""
        return self._path

    @property
    def failure(self) -> Optional[RecordingFailed]:
        """Why the recording ended early, or None."""
        return self._failure

    @property
    def duration_ns(self) -> int:
        """Log time between the first and the last message recorded."""
        return 0 if self._last is None else self._last[0] - self._first_log_time

    def describe(self) -> str:
        """One line for a log: where, how many messages, what span of log time."""
        files = len(self._paths)
        return (f"{self._path}: {self.message_count} messages in {files} file{'' if files == 1 else 's'}, "
                f"{self.duration_ns / 1e9:.2f} s")

    def selects(self, topic: str) -> bool:
        """Whether writes to ``topic`` are recorded."""
        return self._topics is None or topic in self._topics or _absolute(topic) in self._topics

    # ----------------------------------------------------------------- writes
    def write(
        self,
        topic: str,
        type_name: str,
        message,
        log_time_ns: int,
        qos: str = "reliable",
        serialized: Optional[bytes] = None,
    ) -> bool:
        """Record ``message`` (an rclpy message of ``type_name``, e.g.
        ``sensor_msgs/msg/LaserScan``) on ``topic`` at ``log_time_ns``.

        ``serialized`` (CDR bytes of ``message``) skips the serialisation;
        otherwise the message is serialised with its CDR padding bytes zeroed
        (:func:`vmas_ros.record.cdr.serialize_zeroed`).
        ``qos`` ("reliable" or "best_effort") goes to the channel's
        ``offered_qos_profiles`` when the topic is first written. Returns False
        (and does nothing) for a topic the filter does not select.
        """
        if not self.selects(topic):
            return False
        if serialized is None:
            if message is None:
                raise TypeError("write() needs a message or serialized bytes")
            from vmas_ros.record.cdr import serialize_zeroed

            serialized = serialize_zeroed(message)  # padding zeroed: same message, same bytes
        return self._record(topic, type_name, serialized, log_time_ns, qos)

    def write_raw(
        self, topic: str, type_name: str, cdr_bytes: bytes, log_time_ns: int, qos: str = "reliable"
    ) -> bool:
        """Record CDR bytes (with their 4-byte encapsulation header) of ``type_name``,
        for types without an importable Python class, such as /tf's TFMessage
        (see :func:`serialize_tf_message`). Returns False for an unselected topic."""
        if not self.selects(topic):
            return False
        return self._record(topic, type_name, cdr_bytes, log_time_ns, qos)

    def _record(self, topic: str, type_name: str, data, log_time_ns: int, qos: str) -> bool:
        names = self._names.get((topic, type_name))
        if names is None:  # first use of this (topic, type) spelling: validate once
            pkg, name = normalize_type(type_name)
            names = self._names[(topic, type_name)] = (_absolute(topic), f"{pkg}/msg/{name}")
        topic, type_name = names
        if qos not in _QOS:
            qos_profile_yaml(qos)  # raises the error
        log_time = int(log_time_ns)
        if log_time != log_time_ns or log_time < 0 or log_time >= 2**64:
            raise ValueError(f"log_time_ns must be a non-negative integer of nanoseconds, not {log_time_ns!r}")
        if type(data) is not bytes:
            data = bytes(data)
        with self._deferred_signals(), self._lock:
            return self._record_locked(topic, type_name, data, log_time, qos)

    def _record_locked(self, topic: str, type_name: str, data: bytes, log_time: int, qos: str) -> bool:
        if self._failure is not None:
            return False  # the recording ended at a write error (reported once)
        if self._closed:
            raise RuntimeError(f"the recorder of {self._path} is closed")
        known = self._types.get(topic)
        if known is None:
            definition = self._definitions.get(type_name)
            if definition is None:
                definition = self._definitions[type_name] = message_definition(type_name)
            known = self._types[topic] = (type_name, {"offered_qos_profiles": qos_profile_yaml(qos)})
        elif known[0] != type_name:
            raise ValueError(f"topic {topic} is recorded as {known[0]}; cannot also record {type_name} on it")
        if self._last is not None and log_time < self._last[0]:
            raise ValueError(
                f"log time went backwards on {topic}: {log_time} ns after {self._last[0]} ns "
                f"(on {self._last[1]}); log times must not decrease"
            )
        count = self._counts.get(topic, 0)
        try:
            f = self._file
            if f is not None and f.messages and self._full(f, log_time, len(data)):
                self._close_file()
                f = None
            if f is None:
                self._open_next()
                f = self._file
            channel_id = f.channel(topic, type_name, self._definitions[type_name], known[1])
            f.add(channel_id, data, log_time, count % 2**32)
        except OSError as error:
            self._fail(error, pending=1)  # the message was handed over: it may be in the last chunk
            return False
        self._counts[topic] = count + 1
        if self._first_log_time is None:
            self._first_log_time = log_time
        self._last = (log_time, topic)
        return True

    def _full(self, f: _OpenFile, log_time: int, data_bytes: int) -> bool:
        if self._max_duration_ns is not None and log_time - f.first_log_time > self._max_duration_ns:
            return True
        if self._max_bytes is not None:
            grows = data_bytes + _MESSAGE_RECORD_OVERHEAD + _INDEX_ENTRY + _INDEX_OVERHEAD
            return f.size() + grows > self._max_bytes
        return False

    def _open_next(self) -> None:
        path = self._layout.file_path(len(self._paths))
        self._opening = path  # what a RecordingFailed names if creating it fails
        self._file = _OpenFile(path, self._chunk_size, self._compression)
        self._paths.append(path)

    def _close_file(self) -> None:
        f = self._file
        if f is not None:
            f.close()
            self._file = None
            self._finished.append((f.path, f.messages))

    def _fail(self, error: OSError, pending: int = 0) -> None:
        """End the recording at a write error: keep what is on disk, report once."""
        f, self._file = self._file, None
        safe = sum(n for path, n in self._finished if path.exists())  # a vanished folder took them along
        if f is not None:
            safe += f.flushed_messages if f.path.exists() else 0
            f.abandon()
        self._closed = True
        atexit.unregister(self.close)
        self._failure = RecordingFailed(
            self._path, error.filename or (f.path if f is not None else self._opening), error, safe,
            self.message_count + pending, unfinished=f is not None, folder=isinstance(self._layout, BagFolder),
        )
        if self._on_failure is None:
            raise self._failure
        self._on_failure(self._failure)

    @contextlib.contextmanager
    def _deferred_signals(self) -> Iterator[None]:
        if not self._defer or self._deferring or threading.get_ident() != _MAIN_THREAD_ID:
            yield
            return
        old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, _DEFERRED)
        noted: list = []
        # Python handlers (signal.getsignal is callable) are held; handlers installed from C
        # (getsignal is None, e.g. rclpy's) run outside Python bytecode and are left alone.
        # A handler that can hold signals itself (hold/release, e.g. vmas_ros.ros.signal_guard's)
        # stays installed: swapping it would drop a C handler chained in front of it (rclpy's)
        holders, held = [], {}
        for sig in _DEFERRED:
            handler = signal.getsignal(sig)
            if hasattr(handler, "hold") and hasattr(handler, "release"):
                if handler not in holders:
                    holders.append(handler)
            elif callable(handler):
                held[sig] = handler
        for holder in holders:
            holder.hold()
        for sig in held:
            signal.signal(sig, lambda signum, frame: noted.append(signum))
        self._deferring += 1
        try:
            yield
        finally:
            self._deferring -= 1
            for sig, handler in held.items():
                signal.signal(sig, handler)
            signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
            for holder in holders:  # a signal it noted acts now (e.g. raises KeyboardInterrupt)
                holder.release()
            for signum in noted:  # now, between writes, as if it had just arrived
                held[signum](signum, None)

    @contextlib.contextmanager
    def batch(self) -> Iterator[None]:
        """A context for a group of writes (e.g. one simulation step): signals are
        deferred once for the group, and other threads wait until it ends."""
        with self._deferred_signals(), self._lock:
            yield

    # --------------------------------------------------------------- lifecycle
    def flush(self) -> None:
        """Write the open chunk to the file now (a smaller chunk, nothing lost on a kill)."""
        with self._deferred_signals(), self._lock:
            if not self._closed and self._file is not None:
                try:
                    self._file.flush()
                except OSError as error:
                    self._fail(error)

    def close(self) -> None:
        """Finish the current file (summary, statistics, indexes). Idempotent."""
        with self._deferred_signals(), self._lock:
            if self._closed:
                return
            self._closed = True
            atexit.unregister(self.close)
            try:
                self._close_file()
                self._layout.finish(self._paths)
            except OSError as error:
                self._fail(error)
            finally:
                self._claim.release()

    def __enter__(self) -> "McapRecorder":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return f"McapRecorder({str(self._path)!r}, {state}, {self.message_count} messages in {len(self._paths)} files)"
