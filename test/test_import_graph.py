"""No import circles in vmas_ros, between files or between folders, and no folder reaching into another's
private names; plus the graph reader (test/import_graph.py) tried on small packages written for the test.

Layers keep the package readable: a module can be understood from the modules
below it, and a folder changed without breaking the folders below it. A circle
makes every file in it depend on all the others, so the tests below fail on the
first one and name it.
"""
from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Dict

import pytest

from test import import_graph as ig

ROOT = Path(__file__).resolve().parents[1]

#: modules (with everything below them) whose imports are left out of the folder graph, each with its reason
MIRRORS: Dict[str, str] = {
    "vmas_ros.simulator.environment": "VMAS's module path vmas.simulator.environment, re-exporting envs/",
}


@pytest.fixture(scope="module")
def graph():
    return ig.import_graph(ROOT)


@pytest.fixture(scope="module")
def packages():
    return ig.packages_of(ig.modules_of(ROOT))


def test_no_file_imports_itself_through_others(graph):
    assert ig.circles(graph) == []


def test_no_folder_imports_a_folder_that_imports_it(graph, packages):
    assert ig.circles(ig.folder_graph(graph, packages, skip=MIRRORS)) == []


def test_every_mirror_exists_and_is_needed(graph, packages):
    """A mirror that no longer exists, or whose imports close no circle, is dropped from MIRRORS."""
    for mirror in MIRRORS:
        assert mirror in graph, f"{mirror} is not a module of vmas_ros"
        others = [m for m in MIRRORS if m != mirror]
        assert ig.circles(ig.folder_graph(graph, packages, skip=others)), f"{mirror} closes no circle"


def test_no_module_imports_another_folders_private_names():
    assert ig.private_imports(ROOT) == []


# ------------------------------------------------------------- the reader, on small packages
def write_package(root: Path, files: Dict[str, str]) -> Path:
    """Write ``files`` (path under ``root`` -> source) and return ``root``."""
    for name, source in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(source), encoding="utf-8")
    return root


def test_a_two_file_circle_is_found(tmp_path):
    root = write_package(tmp_path, {
        "pkg/__init__.py": "",
        "pkg/a.py": "from pkg.b import B\n",
        "pkg/b.py": "def f():\n    from pkg import a  # lazy: still ties the two files\n",
    })
    assert ig.circles(ig.import_graph(root, "pkg")) == [["pkg.a", "pkg.b"]]


def test_an_init_importing_its_submodules_is_no_circle(tmp_path):
    """``from pkg import sub`` is an edge to the submodule, not to pkg/__init__.py."""
    root = write_package(tmp_path, {
        "pkg/__init__.py": "from pkg import sub\nfrom pkg.other import X\n",
        "pkg/sub.py": "from pkg import other\n",
        "pkg/other.py": "X = 1\n",
    })
    graph = ig.import_graph(root, "pkg")
    assert graph == {"pkg": {"pkg.sub", "pkg.other"}, "pkg.sub": {"pkg.other"}, "pkg.other": set()}
    assert ig.circles(graph) == []


def test_a_submodule_reading_names_of_its_init_is_a_circle(tmp_path):
    root = write_package(tmp_path, {
        "pkg/__init__.py": "from pkg.sub import f\nNAMES = {}\n",
        "pkg/sub.py": "from pkg import NAMES\n",
    })
    assert ig.circles(ig.import_graph(root, "pkg")) == [["pkg", "pkg.sub"]]


def test_relative_imports_resolve_and_type_checking_imports_do_not_count(tmp_path):
    root = write_package(tmp_path, {
        "pkg/__init__.py": "",
        "pkg/inner/__init__.py": "from . import a\n",
        "pkg/inner/a.py": "from typing import TYPE_CHECKING\nfrom ..top import T\nif TYPE_CHECKING:\n"
                          "    from pkg.inner.b import B\n",
        "pkg/inner/b.py": "from .a import T\n",
        "pkg/top.py": "T = int\n",
    })
    graph = ig.import_graph(root, "pkg")
    assert graph["pkg.inner"] == {"pkg.inner.a"}
    assert graph["pkg.inner.a"] == {"pkg.top"}
    assert graph["pkg.inner.b"] == {"pkg.inner.a"}
    assert ig.circles(graph) == []


def test_folders_and_their_circles(tmp_path):
    """Top-level files form the folder of the package itself; a skipped module's imports leave the graph."""
    root = write_package(tmp_path, {
        "pkg/__init__.py": "",
        "pkg/top.py": "import pkg.x.a\n",
        "pkg/x/__init__.py": "",
        "pkg/x/a.py": "from pkg.y.b import B\n",
        "pkg/x/c.py": "C = 1\n",
        "pkg/y/__init__.py": "",
        "pkg/y/b.py": "B = 1\n",
        "pkg/y/mirror.py": "from pkg.x.c import C\n",
    })
    graph = ig.import_graph(root, "pkg")
    packages = ig.packages_of(ig.modules_of(root, "pkg"))
    assert ig.folder_of("pkg.top", packages, "pkg") == "pkg"
    assert ig.folder_of("pkg.x.a", packages, "pkg") == "pkg.x"
    assert ig.folder_of("pkg.x", packages, "pkg") == "pkg.x"
    folders = ig.folder_graph(graph, packages, "pkg")
    assert folders == {"pkg": {"pkg.x"}, "pkg.x": {"pkg.y"}, "pkg.y": {"pkg.x"}}
    assert ig.circles(folders) == [["pkg.x", "pkg.y"]]
    assert ig.circles(ig.folder_graph(graph, packages, "pkg", skip=["pkg.y.mirror"])) == []


def test_private_names_of_another_folder_are_found(tmp_path):
    root = write_package(tmp_path, {
        "pkg/__init__.py": "from pkg.x import __version__\n",
        "pkg/x/__init__.py": "__version__ = '1'\n",
        "pkg/x/a.py": "from pkg.x._io import _read\nfrom ._io import _read\n_HIDDEN = 1\n",
        "pkg/x/_io.py": "def _read():\n    pass\n",
        "pkg/y/__init__.py": "",
        "pkg/y/b.py": "from pkg.x.a import _HIDDEN\n\ndef f():\n    from pkg.x import _io\n",
    })
    assert ig.private_imports(root, "pkg") == [("pkg.y.b", "pkg.x._io"), ("pkg.y.b", "pkg.x.a._HIDDEN")]
