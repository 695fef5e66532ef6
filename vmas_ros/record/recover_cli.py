"""``vmas-ros bag-recover IN [OUT]``: turn the bag of a killed recorder into a finished bag.

A recorder killed with SIGKILL (or a crash, or a power cut) leaves an MCAP
with no summary and no footer; many readers refuse it. This command runs
:func:`vmas_ros.record.recover.recover` and says what it kept and what was
lost, so the user can judge the recovered bag without opening it:

* messages kept, per topic, and the span of their log times;
* bytes of the input that could not be used (the partly written chunk, or
  whatever follows the first damaged record);
* whether the input was in fact complete (then nothing was lost and OUT is
  a rewritten copy).

IN may also be a rosbag2 bag folder (``NAME/NAME_<n>.mcap``), typically one
without ``metadata.yaml`` because its recorder died: OUT (default
``NAME.recovered``) is then a new bag folder holding the complete files as
they are (hard links where the filesystem allows, else copies), the damaged
ones recovered, and a ``metadata.yaml`` rebuilt from the files.

It never touches the input, and refuses to overwrite an existing OUT unless
``--force``; even then OUT is written beside itself under a temporary name and
moved into place only when finished, so an interrupted or failed recovery
never leaves a half-written OUT (nor destroys the old one).

Exit codes: 0 when OUT was written, 2 for a usage error (missing input, not an
MCAP file, OUT exists, OUT is IN), 1 when the recovery itself failed.
Also runnable as ``python -m vmas_ros.record.recover_cli``.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Dict, List, Optional

from vmas_ros.record.recover import recover
from vmas_ros.record.rosbag2 import folder_files, metadata_from_files, write_metadata

PROG = "vmas-ros bag-recover"


def default_output(path_in: Path) -> Path:
    """``run.mcap`` -> ``run.recovered.mcap`` beside it (the suffix tells what the file is);
    a bag folder ``run`` -> ``run.recovered``."""
    if path_in.is_dir():
        return path_in.with_name(f"{path_in.name}.recovered")
    stem = path_in.name[: -len(".mcap")] if path_in.name.endswith(".mcap") else path_in.name
    return path_in.with_name(f"{stem}.recovered.mcap")


def add_parser(sub) -> argparse.ArgumentParser:
    """Add the ``bag-recover`` subcommand to ``sub`` (an argparse subparsers object); returns it."""
    parser = sub.add_parser(
        "bag-recover", help="rebuild a finished MCAP bag from one whose recorder was killed",
        description="Copy every complete message of a (possibly truncated) MCAP bag to a new, finished "
                    "MCAP file, and report what was kept and what was lost.",
    )
    add_arguments(parser)
    parser.set_defaults(func=run)
    return parser


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The command's arguments (shared by ``vmas-ros bag-recover`` and ``python -m``)."""
    parser.add_argument("input", metavar="IN", help="the damaged .mcap file or bag folder (it is only read)")
    parser.add_argument("output", metavar="OUT", nargs="?", default=None,
                        help="the recovered file or folder (default: IN with .recovered.mcap, or "
                             "FOLDER.recovered)")
    parser.add_argument("--force", action="store_true", help="replace OUT if it exists")
    parser.add_argument("--compression", choices=("zstd", "lz4", "none"), default="zstd",
                        help="chunk compression of OUT (default zstd)")
    parser.add_argument("--json", action="store_true", help="print the report as one JSON object")


def _error(message: str, code: int = 2) -> int:
    print(f"{PROG}: {message}", file=sys.stderr)
    return code


def _check_paths(path_in: Path, path_out: Path, force: bool) -> Optional[str]:
    """Why the recovery must not start (None: it may)."""
    if not path_in.exists():
        return f"{path_in}: no such file"
    if path_in.is_dir():
        if not folder_files(path_in):
            return f"{path_in}: a folder without NAME_<n>.mcap files, not a bag folder"
        if path_out.exists() and path_out.resolve() == path_in.resolve():
            return f"{path_out}: OUT is the input; recovery writes a new folder (choose another OUT)"
        if path_out.exists() and not path_out.is_dir():
            return f"{path_out}: OUT is a file; a bag folder recovers into a folder"
        if path_out.exists() and not force:
            return f"{path_out} exists; pass --force to replace it"
        return None
    if path_in.stat().st_size == 0:
        return f"{path_in}: empty file, nothing to recover (the recorder wrote nothing)"
    if path_out.exists() and path_out.resolve() == path_in.resolve():
        return f"{path_out}: OUT is the input; recovery writes a new file (choose another OUT)"
    if path_out.is_dir():
        return f"{path_out}: OUT is a directory"
    if path_out.exists() and not force:
        return f"{path_out} exists; pass --force to replace it"
    if not path_out.parent.is_dir():
        return f"{path_out.parent}: no such directory for OUT"
    return None


def describe(report: Dict[str, object], path_in: Path, path_out: Path) -> List[str]:
    """The report as lines for a person: what was kept, what was lost and why."""
    used, total = int(report["bytes_used"]), int(report["bytes_total"])
    files = report.get("files")
    if files is not None:  # a bag folder
        lines = [f"recovered {report['messages']} messages on {report['channels']} topics from {len(files)} "
                 f"file{'' if len(files) == 1 else 's'} of {path_in} into {path_out} (metadata.yaml rebuilt)"]
        lines += [f"  {name}: {'complete' if state == 'complete' else 'recovered up to the damage'}"
                  for name, state in files.items()]
    else:
        lines = [f"recovered {report['messages']} messages on {report['channels']} topics "
                 f"({report['chunks']} chunk{'' if report['chunks'] == 1 else 's'}) from {path_in} into {path_out}"]
    for topic, count in sorted(report["topics"].items()):
        lines.append(f"  {topic}: {count}")
    if report.get("first_log_time_ns") is not None:
        lines.append(f"log times {report['first_log_time_ns'] / 1e9:.3f} s to {report['last_log_time_ns'] / 1e9:.3f} s")
    if report["complete"]:
        lines.append("the input was complete (it had its data end record): nothing was lost; "
                     "the summary was rebuilt")
    else:
        lines.append(f"lost: {total - used} of {total} bytes after the last complete record "
                     f"(a chunk cut off by the kill, or damage); messages the recorder still held in "
                     f"memory never reached the file")
        lines.append(f"reading stopped at byte {used}: {report['error'] or 'the file ends there'}")
    return lines


def recover_file(path_in: Path, path_out: Path, compression: str = "zstd") -> Dict[str, object]:
    """``recover`` into a temporary file beside ``path_out``, moved into place only once finished.

    Adds ``first_log_time_ns`` / ``last_log_time_ns`` (None without messages)
    to the report: the span of time the recovered bag covers.
    """
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path_out.name}.", suffix=".partial", dir=path_out.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes it private; OUT gets the mode of any new file
    try:
        report = recover(path_in, tmp, compression=compression)
        report.update(_log_time_span(tmp))
        os.replace(tmp, path_out)
    finally:
        tmp.unlink(missing_ok=True)
    return report


def recover_folder(folder_in: Path, folder_out: Path, compression: str = "zstd") -> Dict[str, object]:
    """Recover the bag folder ``folder_in`` into a new folder ``folder_out`` with a rebuilt metadata.yaml.

    The new folder is built beside ``folder_out`` under a temporary name and
    moved into place when finished (an existing ``folder_out`` is replaced
    then). The report adds up the files' reports (``files``: per file name,
    ``"complete"`` or the recovery's error).
    """
    parent = folder_out.parent
    tmp = Path(tempfile.mkdtemp(prefix=f".{folder_out.name}.", suffix=".partial", dir=parent))
    report: Dict[str, object] = {"messages": 0, "topics": {}, "chunks": 0, "schemas": 0, "channels": 0,
                                 "complete": True, "error": None, "bytes_used": 0, "bytes_total": 0, "files": {}}
    try:
        os.chmod(tmp, 0o777 & ~_umask())
        for path in folder_files(folder_in):
            target = tmp / path.name
            if _finished(path):
                _link_or_copy(path, target)
                size = path.stat().st_size
                part = {"complete": True, "error": None, "bytes_used": size, "bytes_total": size}
            else:
                part = recover(path, target, compression=compression)
                report["complete"] = False
                report["error"] = report["error"] or f"{path.name}: {part['error']}"
            report["files"][path.name] = "complete" if part["complete"] else part["error"]
            report["bytes_used"] += part["bytes_used"]
            report["bytes_total"] += part["bytes_total"]
        info = metadata_from_files(folder_files(tmp))
        write_metadata(tmp, info)
        report["messages"] = info["message_count"]  # the files' own summaries count them
        for entry in info["topics_with_message_count"]:
            report["topics"][entry["topic_metadata"]["name"]] = entry["message_count"]
        report["channels"] = len(report["topics"])
        start = info["starting_time"]["nanoseconds_since_epoch"]
        report["first_log_time_ns"] = start if info["message_count"] else None
        report["last_log_time_ns"] = start + info["duration"]["nanoseconds"] if info["message_count"] else None
        if folder_out.exists():
            shutil.rmtree(folder_out)
        os.replace(tmp, folder_out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return report


def _umask() -> int:
    """The process's umask (reading it means setting it; it is set back at once)."""
    umask = os.umask(0)
    os.umask(umask)
    return umask


def _finished(path: Path) -> bool:
    """Whether ``path`` is a complete MCAP (its summary reads)."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as stream:
            return make_reader(stream).get_summary() is not None
    except Exception:  # mcap raises several kinds for a cut-off file
        return False


def _link_or_copy(source: Path, target: Path) -> None:
    try:
        os.link(source, target)
    except OSError:  # another filesystem, or links not allowed: copy
        shutil.copyfile(source, target)


def _log_time_span(path: Path) -> Dict[str, Optional[int]]:
    from mcap.reader import make_reader

    with open(path, "rb") as stream:
        statistics = make_reader(stream).get_summary().statistics
    if statistics is None or statistics.message_count == 0:
        return {"first_log_time_ns": None, "last_log_time_ns": None}
    return {"first_log_time_ns": statistics.message_start_time, "last_log_time_ns": statistics.message_end_time}


def run(args: argparse.Namespace) -> int:
    """Run the command for parsed ``args``; returns the exit code."""
    path_in = Path(args.input)
    path_out = Path(args.output) if args.output else default_output(path_in)
    problem = _check_paths(path_in, path_out, args.force)
    if problem is not None:
        return _error(problem)
    try:
        if path_in.is_dir():
            report = recover_folder(path_in, path_out, args.compression)
        else:
            report = recover_file(path_in, path_out, args.compression)
    except ValueError as error:  # not an MCAP file, or refused paths
        return _error(str(error))
    except OSError as error:
        return _error(f"{error.filename or path_in}: {error.strerror or error}")
    except Exception as error:  # the recovery itself broke: say so, keep the traceback out of the way
        return _error(f"recovering {path_in} failed: {type(error).__name__}: {error}", 1)
    if args.json:
        print(json.dumps({"input": str(path_in), "output": str(path_out), **report}, sort_keys=True))
    else:
        print("\n".join(describe(report, path_in, path_out)))
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    """``python -m vmas_ros.record.recover_cli IN [OUT] [--force]``."""
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.splitlines()[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
