"""Run VMAS 1.5.2's own test suite against vmas_ros: VMAS's tests as our oracle.

    python -m test.compat.vmas_suite                      # the tests VMAS's source distribution carries
    python -m test.compat.vmas_suite --repo GIT_DIR       # also test_scenarios/ and test_wrappers/
    python -m test.compat.vmas_suite -- -x -k lidar       # after --, arguments for pytest
    python -m test.compat.vmas_suite --on-vmas [--repo GIT_DIR]   # the same tests on VMAS itself

VMAS's sdist carries ``tests/test_vmas.py`` and ``tests/test_lidar.py``; its
``tests/test_scenarios/`` and ``tests/test_wrappers/`` exist only in its git
repository (``--repo``: a clone or a bare git directory, read at tag
``VMAS-1.5.2``). Nothing from VMAS is kept in this repository: the sdist is
downloaded from the package index into a cache (``--cache``), and the tests
are unpacked into a scratch folder for the run.

In that folder a ``conftest.py`` calls ``vmas_ros.install_as_vmas()`` before
anything imports ``vmas`` (or torchrl), and checks that ``vmas.make_env`` is
ours. ``test_vmas.py`` lists the scenarios by globbing ``../vmas/scenarios``
beside itself, so that folder holds one link per registered vmas_ros scenario,
under VMAS's layout (``mpe/``, ``debug/``): it collects ours.

``--on-vmas`` runs the same tests on the installed VMAS 1.5.2 instead (no
conftest, and ``vmas/`` beside the tests is VMAS's own package): the yardstick
for the time the suite takes on vmas_ros. The suite runs as a user's would, in
vmas_ros's default mode unless ``VMAS_ROS_COMPILE`` says otherwise.

Prints pytest's summary and ``vmas suite on vmas_ros: N passed, N failed, N
skipped in S s`` (``on VMAS 1.5.2`` with ``--on-vmas``); exits with pytest's
exit code.
"""
from __future__ import annotations

import argparse
import importlib
import importlib.util
import re
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path
from typing import Dict, List, Optional

VMAS_VERSION = "1.5.2"
TAG = f"VMAS-{VMAS_VERSION}"
SDIST_TESTS = ("tests/test_vmas.py", "tests/test_lidar.py")
REPO_TESTS = ("tests/test_scenarios", "tests/test_wrappers")
DEFAULT_CACHE = Path.home() / ".cache" / "vmas_ros" / "vmas_sdist"

CONFTEST = '''\
"""Written by vmas_ros's test/compat/vmas_suite.py: VMAS's tests run on vmas_ros."""
import vmas_ros

vmas = vmas_ros.install_as_vmas()
assert vmas.make_env is vmas_ros.make_env, "vmas.make_env is not vmas_ros's"
'''


def sdist(cache: Path) -> Path:
    """VMAS's source distribution, downloaded from the package index into ``cache`` once."""
    cache.mkdir(parents=True, exist_ok=True)
    found = sorted(cache.glob(f"vmas-{VMAS_VERSION}.tar.gz"))
    if not found:
        # into a folder of this process's own, then renamed into place: two runs at once (the suite's
        # workers) never see each other's half-written file
        with tempfile.TemporaryDirectory(dir=cache, prefix=".download_") as private:
            subprocess.run(
                [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--no-binary", ":all:",
                 f"vmas=={VMAS_VERSION}", "--dest", private],
                check=True,
            )
            for archive in Path(private).glob(f"vmas-{VMAS_VERSION}.tar.gz"):
                archive.replace(cache / archive.name)
        found = sorted(cache.glob(f"vmas-{VMAS_VERSION}.tar.gz"))
    if not found:
        raise FileNotFoundError(f"pip download did not leave vmas-{VMAS_VERSION}.tar.gz in {cache}")
    return found[0]


def unpack_sdist_tests(archive: Path, into: Path) -> List[Path]:
    """``SDIST_TESTS`` from the archive into ``into/tests``; returns their paths."""
    out = []
    with tarfile.open(archive) as tar:
        for name in SDIST_TESTS:
            member = tar.getmember(f"vmas-{VMAS_VERSION}/{name}")
            data = tar.extractfile(member).read()
            target = into / name
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
            out.append(target)
    return out


def unpack_repo_tests(repo: Path, into: Path) -> List[Path]:
    """``REPO_TESTS`` at tag ``TAG`` of the git repository ``repo`` into ``into/tests``."""
    git_dir = repo / ".git" if (repo / ".git").exists() else repo
    archive = subprocess.run(
        ["git", f"--git-dir={git_dir}", "archive", "--format=tar", TAG, *REPO_TESTS],
        check=True, capture_output=True,
    ).stdout
    with tempfile.TemporaryFile() as handle:
        handle.write(archive)
        handle.seek(0)
        with tarfile.open(fileobj=handle) as tar:
            tar.extractall(into, filter="data")
    return [into / name for name in REPO_TESTS]


def link_scenarios(into: Path) -> int:
    """``into/vmas/scenarios``: a link per registered scenario to its module file, in VMAS's layout."""
    from vmas_ros.scenarios import DEBUG_SCENARIOS, MPE_SCENARIOS, REGISTRY

    root = into / "vmas" / "scenarios"
    for name in REGISTRY:
        folder = root / ("mpe" if name in MPE_SCENARIOS else "debug" if name in DEBUG_SCENARIOS else "")
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"{name}.py").symlink_to(Path(importlib.import_module(REGISTRY[name]).__file__))
    return len(REGISTRY)


def summary(output: str) -> Dict[str, int]:
    """Counts from pytest's closing line (``3 passed, 1 failed, 2 skipped in ...``)."""
    counts = {"passed": 0, "failed": 0, "skipped": 0, "errors": 0}
    last = [line for line in output.splitlines() if re.search(r"\d+ (passed|failed|error)", line)]
    for number, word in re.findall(r"(\d+) (passed|failed|skipped|errors?)", last[-1] if last else ""):
        counts["errors" if word.startswith("error") else word] = int(number)
    return counts


def link_vmas(into: Path) -> Path:
    """``into/vmas``: a link to the installed VMAS package (``--on-vmas``); its version must be ``VMAS_VERSION``."""
    from importlib import metadata

    version = metadata.version("vmas")
    if version != VMAS_VERSION:
        raise SystemExit(f"--on-vmas needs vmas=={VMAS_VERSION} installed, found {version}")
    package = Path(importlib.util.find_spec("vmas").origin).parent
    (into / "vmas").symlink_to(package)
    return package


def run(repo: Optional[Path], cache: Path, pytest_args: List[str], on_vmas: bool = False) -> int:
    side = f"VMAS {VMAS_VERSION}" if on_vmas else "vmas_ros"
    with tempfile.TemporaryDirectory(prefix="vmas_suite_") as scratch:
        where = Path(scratch)
        paths = unpack_sdist_tests(sdist(cache), where)
        if repo is not None:
            paths += unpack_repo_tests(repo, where)
        if on_vmas:
            found = f"VMAS's own scenarios from {link_vmas(where)}"
        else:
            (where / "tests" / "conftest.py").write_text(CONFTEST)
            found = f"{link_scenarios(where)} scenarios linked"
        print(f"vmas suite on {side}: {', '.join(str(p.relative_to(where)) for p in paths)}; {found}")
        command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rfE",
                   f"--rootdir={where}", *[str(p) for p in paths], *pytest_args]
        start = time.perf_counter()
        result = subprocess.run(command, cwd=where, capture_output=True, text=True)
        seconds = time.perf_counter() - start
        print(result.stdout[-20000:], result.stderr[-5000:], sep="\n")
        counts = summary(result.stdout)
        print(f"vmas suite on {side}: {counts['passed']} passed, {counts['failed']} failed, "
              f"{counts['skipped']} skipped" + (f", {counts['errors']} errors" if counts["errors"] else "")
              + f" in {seconds:.0f} s")
        return result.returncode


def main(argv: Optional[List[str]] = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    pytest_args = argv[argv.index("--") + 1:] if "--" in argv else []
    own = argv[: argv.index("--")] if "--" in argv else argv
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repo", type=Path, help="VMAS's git repository (a clone or a bare git dir)")
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE, help="where the sdist is kept")
    parser.add_argument("--on-vmas", action="store_true",
                        help=f"run the tests on the installed VMAS {VMAS_VERSION} itself (to time the suite there)")
    args = parser.parse_args(own)
    return run(args.repo, args.cache, pytest_args, on_vmas=args.on_vmas)


if __name__ == "__main__":
    sys.exit(main())
