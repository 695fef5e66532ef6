"""vmas_ros's import graph, read from the source with ``ast`` (nothing is imported), and its circles.

How an import becomes an edge between two files (modules):

* ``import a.b.c`` and ``from a.b.c import name``: an edge to the deepest
  module among ``a.b.c``, ``a.b``, ``a`` that is a file of the package;
* ``from a.b import c`` where ``a/b/c.py`` (or ``a/b/c/``) exists: an edge to
  ``a.b.c`` only, not to ``a/b/__init__.py``. Python runs the package's
  ``__init__`` first, but the file depends on the submodule; counting the
  ``__init__`` too would make every package whose ``__init__`` re-exports a
  submodule look circular with each sibling that imports a neighbour;
* a package's ``__init__`` importing its own submodules is an edge like any
  other: ``pkg`` -> ``pkg.sub``. It is a circle only when ``pkg.sub`` imports
  names from ``pkg`` itself (its ``__init__``);
* relative imports are resolved against the importing file's package;
* imports inside functions count (a lazy import still ties the two files),
  imports under ``if TYPE_CHECKING:`` do not (they never run).

A folder is a first-level subpackage of ``vmas_ros`` (``vmas_ros.ros``,
``vmas_ros.simulator``...); the package's own top-level files form the folder
``vmas_ros``. Folder edges are the file edges between different folders.
A private name is one that starts with an underscore (dunders such as
``__version__`` are not private): a module ``_io`` or a name ``_helper``;
:func:`private_imports` lists the imports of such names from another folder.

Every function takes the package's name (``vmas_ros`` by default), so the
reader can be tried on a small package of its own (test_import_graph.py).
Run this file to print the circles and the folder graph.
"""
from __future__ import annotations

import ast
from pathlib import Path
from typing import Dict, Iterable, Iterator, List, Mapping, Optional, Set, Tuple

PACKAGE = "vmas_ros"


def modules_of(root: Path, package: str = PACKAGE) -> Dict[str, Path]:
    """Every module of ``package`` under ``root`` (the repository): dotted name -> file."""
    found = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        found[".".join(parts)] = path
    return found


def packages_of(modules: Mapping[str, Path]) -> Set[str]:
    """The modules that are packages (a folder with an ``__init__.py``)."""
    return {name for name, path in modules.items() if path.name == "__init__.py"}


def _deepest(name: str, modules: Mapping[str, Path]) -> str:
    parts = name.split(".")
    while parts and ".".join(parts) not in modules:
        parts.pop()
    return ".".join(parts)


def _type_checking_only(node: ast.AST) -> bool:
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)


def _imports(tree: ast.AST) -> Iterable[ast.AST]:
    """Every import statement of ``tree`` outside ``if TYPE_CHECKING:`` blocks."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if _type_checking_only(node):
            stack.extend(node.orelse)
            continue
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        stack.extend(ast.iter_child_nodes(node))


def _in_package(name: str, package: str) -> bool:
    return name == package or name.startswith(package + ".")


def imported_names(name: str, path: Path, modules: Mapping[str, Path]) -> Iterator[Tuple[str, Optional[str]]]:
    """What module ``name`` (file ``path``) imports: ``(module, name)`` pairs, ``name`` None when the
    module itself is imported (``import a.b``, or ``from a import b`` where ``b`` is a submodule)."""
    here = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in _imports(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield _deepest(alias.name, modules), None
            continue
        base = node.module or ""
        if node.level:
            anchor = here.split(".")[: len(here.split(".")) - (node.level - 1)]
            base = ".".join(anchor + ([base] if base else []))
        for alias in node.names:
            submodule = f"{base}.{alias.name}"
            if submodule in modules:
                yield submodule, None
            else:
                yield _deepest(base, modules), alias.name


def edges_of(name: str, path: Path, modules: Mapping[str, Path], package: str = PACKAGE) -> Set[str]:
    """The modules of ``package`` that module ``name`` (file ``path``) imports."""
    return {target for target, _ in imported_names(name, path, modules)
            if target and _in_package(target, package) and target != name}


def import_graph(root: Path, package: str = PACKAGE) -> Dict[str, Set[str]]:
    """module -> the package's modules it imports."""
    modules = modules_of(root, package)
    return {name: edges_of(name, path, modules, package) for name, path in modules.items()}


def folder_of(module: str, packages: Set[str], package: str = PACKAGE) -> str:
    """The folder of ``module``: its first-level subpackage of ``package`` (``packages`` lists the
    subpackages), or ``package`` itself for the package's own top-level files."""
    first = ".".join(module.split(".")[:2])
    return first if first != package and first in packages else package


def folder_graph(graph: Mapping[str, Set[str]], packages: Set[str], package: str = PACKAGE,
                 skip: Iterable[str] = ()) -> Dict[str, Set[str]]:
    """folder -> the folders its files import (itself left out). The imports of the modules named in
    ``skip`` and of the modules below them are left out too."""
    skip = tuple(skip)
    folders: Dict[str, Set[str]] = {}
    for module, targets in graph.items():
        own = folder_of(module, packages, package)
        found = folders.setdefault(own, set())
        if any(module == s or module.startswith(s + ".") for s in skip):
            continue
        found.update(folder_of(t, packages, package) for t in targets)
        found.discard(own)
    return folders


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_imports(root: Path, package: str = PACKAGE) -> List[Tuple[str, str]]:
    """``(importer, what)`` for every import of an underscore name (a module or a name in one) of
    another folder, ``what`` being the dotted path imported."""
    modules = modules_of(root, package)
    packages = packages_of(modules)
    found = []
    for name, path in modules.items():
        own = folder_of(name, packages, package)
        for target, imported in imported_names(name, path, modules):
            if not _in_package(target, package) or folder_of(target, packages, package) == own:
                continue
            what = target if imported is None else f"{target}.{imported}"
            if any(_private(part) for part in what.split(".")):
                found.append((name, what))
    return sorted(found)


def circles(graph: Dict[str, Set[str]]) -> List[List[str]]:
    """The strongly connected components of more than one node (Tarjan), each sorted, largest first."""
    index: Dict[str, int] = {}
    low: Dict[str, int] = {}
    on_stack: Set[str] = set()
    stack: List[str] = []
    found: List[List[str]] = []
    counter = [0]

    def visit(start: str) -> None:
        work = [(start, iter(sorted(graph.get(start, ()))))]
        index[start] = low[start] = counter[0]
        counter[0] += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter[0]
                    counter[0] += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return sorted(found, key=lambda c: (-len(c), c))


def main() -> None:
    root = Path(__file__).resolve().parents[1]
    graph = import_graph(root)
    packages = packages_of(modules_of(root))
    for circle in circles(graph):
        print(len(circle), circle)
    for folder, targets in sorted(folder_graph(graph, packages).items()):
        print(folder, "->", sorted(targets))
    for importer, what in private_imports(root):
        print("private:", importer, "imports", what)


if __name__ == "__main__":
    main()
