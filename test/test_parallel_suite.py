"""The suite's parallel run: every worker in a DDS domain of its own, and what fills the machine runs alone.

scripts/test.sh runs the tests on two pytest-xdist workers, then the ones
marked ``serial`` by themselves. These checks keep that safe as tests are
added: the workers' domains never meet each other or the spare domain
test_rostools uses, and every test that starts a Ray cluster is serial.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from test import conftest

TEST_ROOT = Path(__file__).resolve().parent
#: test_rostools.py's "domain nobody uses": its own domain + this, mod 233
SPARE_DOMAIN_OFFSET = 117


@pytest.mark.parametrize("name, worker", [("gw0", 0), ("gw1", 1), ("gw12", 12), ("", -1), ("master", -1),
                                          ("gwx", -1)])
def test_the_worker_number_is_read_from_xdists_name(monkeypatch, name, worker):
    monkeypatch.setenv("PYTEST_XDIST_WORKER", name)
    assert conftest.xdist_worker() == worker


def test_no_two_domains_of_a_run_meet_for_any_session_domain():
    for base in range(conftest.DOMAINS):
        ours = [(base + conftest.WORKER_DOMAIN_STRIDE * k) % conftest.DOMAINS for k in range(3)]
        spare = [(d + SPARE_DOMAIN_OFFSET) % conftest.DOMAINS for d in ours]
        assert len(set(ours + spare)) == 6, (base, ours, spare)


#: calls that start a Ray cluster
RAY_STARTS = ("ray.init", "LocalCluster", "Cluster")


def _starts_ray(node: ast.AST) -> bool:
    return any(isinstance(c, ast.Call) and ast.unparse(c.func) in RAY_STARTS for c in ast.walk(node))


def test_every_test_that_starts_ray_is_serial():
    """A test starting Ray is marked serial, or its module is; a fixture starting Ray needs its module marked."""
    unmarked = []
    for path in sorted(TEST_ROOT.rglob("test_*.py")):
        tree = ast.parse(path.read_text())
        module_serial = any(isinstance(n, ast.Assign) and any(getattr(t, "id", "") == "pytestmark" for t in n.targets)
                            and "pytest.mark.serial" in ast.unparse(n.value) for n in tree.body)
        if module_serial:
            continue
        for node in tree.body:
            if not isinstance(node, ast.FunctionDef) or not _starts_ray(node):
                continue
            decorators = {ast.unparse(d) for d in node.decorator_list}
            if not (node.name.startswith("test_") and "pytest.mark.serial" in decorators):
                unmarked.append(f"{path.relative_to(TEST_ROOT.parent)}::{node.name}")
    assert not unmarked, f"start a Ray cluster without running serially: {unmarked}"


def test_the_long_files_named_to_start_first_exist():
    missing = [path for path in conftest.LONG_FILES if not (TEST_ROOT.parent / path).is_file()]
    assert not missing, f"test/conftest.py's LONG_FILES names files that are gone: {missing}"
    assert len(set(conftest.LONG_FILES)) == len(conftest.LONG_FILES)


def test_the_long_files_come_first_and_each_file_stays_together():
    class Item:
        def __init__(self, nodeid):
            self.nodeid = nodeid

    names = ["test/a.py::x", "test/b.py::x", "test/b.py::y", conftest.LONG_FILES[1] + "::t",
             conftest.LONG_FILES[0] + "::t", "test/a.py::z", "test/b.py::z"]
    items = [Item(n) for n in names]
    conftest.pytest_collection_modifyitems(None, None, items)
    assert [i.nodeid for i in items] == [conftest.LONG_FILES[0] + "::t", conftest.LONG_FILES[1] + "::t",
                                         "test/b.py::x", "test/b.py::y", "test/b.py::z", "test/a.py::x",
                                         "test/a.py::z"]
