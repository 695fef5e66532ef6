"""Shared fixtures for the vmas_ros test suite."""

import faulthandler
import os
import random
import sys

import pytest
import torch

from vmas_ros.rostools.dds_clean import remove_stuck_segments


def _available_devices():
    devices = ["cpu"]
    if torch.cuda.is_available():
        devices.append("cuda")
    return devices


#: DDS domains run 0..232; worker k of a parallel run (pytest-xdist's ``gwK``) takes the session's domain
#: plus k x this stride, so the workers' nodes never see each other. With test_rostools' "domain nobody
#: uses" (the test's own domain + 117) no two of the domains coincide for up to three workers.
WORKER_DOMAIN_STRIDE = 101
DOMAINS = 233


def xdist_worker() -> int:
    """This process's pytest-xdist worker number (``gw1`` -> 1); -1 outside a parallel run's workers."""
    name = os.environ.get("PYTEST_XDIST_WORKER", "")
    return int(name[2:]) if name.startswith("gw") and name[2:].isdigit() else -1


def pytest_configure(config):
    # Before any test (or collection-time import) creates a ROS context: a DDS
    # domain of this session's own, so parallel sessions don't see each other.
    # scripts/test.sh already exports one; this covers a bare `pytest`.
    if not os.environ.get("ROS_DOMAIN_ID"):
        os.environ["ROS_DOMAIN_ID"] = str(random.randint(1, 100))
    worker = xdist_worker()
    if worker >= 0:
        # a worker inherits the session's domain: each takes its own, and its child
        # processes (nodes, scripts) one torch thread each, as the worker itself
        # runs, so two workers and their nodes share the cores without contending
        base = int(os.environ["ROS_DOMAIN_ID"])
        os.environ["ROS_DOMAIN_ID"] = str((base + WORKER_DOMAIN_STRIDE * worker) % DOMAINS)
        os.environ["OMP_NUM_THREADS"] = "1"
    # DDS discovery on this machine only (also for the nodes the tests start, which
    # inherit the environment): no test ever talks to another host.
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
    # Eager physics unless a test asks for compiling: the default mode compiles every new env's
    # step (seconds each); the tests of that default set it themselves (test_compile_default.py).
    # Nodes and scripts the tests start inherit it.
    os.environ.setdefault("VMAS_ROS_COMPILE", "0")
    # Ray on this machine only: every node binds to 127.0.0.1 (by default Ray takes the
    # host's own address) and nothing is reported to Ray's usage servers.
    os.environ["RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"] = "0"
    os.environ["RAY_USAGE_STATS_ENABLED"] = "0"
    # A ROS process that an earlier run (or a test) killed while it set up Fast DDS's
    # shared memory leaves a segment every later node waits for forever, inside Fast
    # DDS where no Python timeout reaches; test/ros/conftest.py sweeps again before
    # every node it starts.
    remove_stuck_segments()
    # One torch thread for the whole session: the tests step small batches, which run
    # fastest on one thread, and on a busy 2-core machine (CI, or sim_node subprocesses
    # beside the test process) two contended threads make tiny kernels such as
    # index_add take milliseconds instead of microseconds. Results do not depend on it.
    torch.set_num_threads(1)


#: files with a test or a module set-up of a minute or more, longest first. On the workers they start
#: first (scripts/test.sh keeps this order: --no-loadscope-reorder), so that none of them begins late and
#: leaves one worker running it alone at the end; the other files follow, most tests first.
LONG_FILES = (
    "test/compat/test_vmas_suite.py",
    "test/compat/test_benchmarl_export.py",
    "test/scenarios/test_vmas_files.py",
    "test/ros/test_multi_sim.py",
    "test/simulator/test_compiled_physics.py",
    "test/ros/test_rostools.py",
    "test/ros/test_sim_node_bag_folder.py",
    "test/compat/test_torchrl_vmas.py",
)


def pytest_collection_modifyitems(session, config, items):
    """The long files first, in LONG_FILES' order, then the others by their number of tests, most first
    (pytest-xdist's own order for --dist loadfile); within a file, pytest's order."""
    counts: dict = {}
    for item in items:
        path = item.nodeid.split("::", 1)[0]
        counts[path] = counts.get(path, 0) + 1
    rank = {path: i for i, path in enumerate(LONG_FILES)}
    first_seen = {path: i for i, path in enumerate(counts)}

    def key(item):
        path = item.nodeid.split("::", 1)[0]
        return (rank.get(path, len(rank)), -counts[path], first_seen[path])

    items.sort(key=key)  # stable: a file's own tests keep their order


#: a test still running after this many seconds ends the whole run, with every
#: thread's stack on stderr: pytest-timeout's limit (pytest.ini) raises in Python,
#: which cannot stop a thread stuck inside native code
HARD_LIMIT_S = 900


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    faulthandler.dump_traceback_later(HARD_LIMIT_S, exit=True, file=sys.__stderr__)
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()


@pytest.fixture(params=_available_devices())
def device(request):
    """Each available torch device: ``cpu``, plus ``cuda`` when there is one."""
    return torch.device(request.param)


@pytest.fixture(scope="session", autouse=True)
def ros_domain_id():
    """The session's ROS_DOMAIN_ID (set in pytest_configure if it was unset)."""
    value = os.environ.get("ROS_DOMAIN_ID", "")
    if not value:
        value = str(random.randint(1, 100))
        os.environ["ROS_DOMAIN_ID"] = value
    assert value.isdigit() and 0 <= int(value) <= 232, f"bad ROS_DOMAIN_ID={value!r}"
    return int(value)
