"""``vmas-ros bag-recover IN [OUT]``: turn the bag of a killed recorder into a finished MCAP.

A recorder killed with SIGKILL (or a crash, or a power cut) leaves an MCAP
with no summary and no footer; many readers refuse it. This command runs
:func:`vmas_ros.record.recover.recover` and says what it kept and what was
lost, so the user can judge the recovered bag without opening it:

* messages kept, per topic, and the span of their log times;
* bytes of the input that could not be used (the partly written chunk, or
  whatever follows the first damaged record);
* whether the input was in fact complete (then nothing was lost and OUT is
  a rewritten copy).

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
import sys
import tempfile
from pathlib import Path
from typing import Dict, List, Optional

from vmas_ros.record.recover import recover

PROG = "vmas-ros bag-recover"


def default_output(path_in: Path) -> Path:
    """``run.mcap`` -> ``run.recovered.mcap`` beside it (the suffix tells what the file is)."""
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
    parser.add_argument("input", metavar="IN", help="the damaged .mcap file (it is only read)")
    parser.add_argument("output", metavar="OUT", nargs="?", default=None,
                        help="the recovered file (default: IN with .recovered.mcap)")
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
        return f"{path_in}: is a directory; give the .mcap file inside it"
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
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes it private; OUT gets the mode of any new file
    try:
        report = recover(path_in, tmp, compression=compression)
        report.update(_log_time_span(tmp))
        os.replace(tmp, path_out)
    finally:
        tmp.unlink(missing_ok=True)
    return report


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
