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
"""
from __future__ import annotations

import ast
from pathlib import Path
from typing import Dict, Iterable, List, Set

PACKAGE = "vmas_ros"


def modules_of(root: Path) -> Dict[str, Path]:
    """Every module of the package under ``root`` (the repository): dotted name -> file."""
    found = {}
    for path in sorted((root / PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        found[".".join(parts)] = path
    return found


def _is_package(name: str, modules: Dict[str, Path]) -> bool:
    return name in modules and modules[name].name == "__init__.py"


def _deepest(name: str, modules: Dict[str, Path]) -> str:
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


def edges_of(name: str, path: Path, modules: Dict[str, Path]) -> Set[str]:
    """The modules of the package that module ``name`` (file ``path``) imports."""
    here = name if path.name == "__init__.py" else name.rpartition(".")[0]
    targets: Set[str] = set()
    for node in _imports(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            targets.update(_deepest(alias.name, modules) for alias in node.names)
            continue
        base = node.module or ""
        if node.level:
            anchor = here.split(".")[: len(here.split(".")) - (node.level - 1)]
            base = ".".join(anchor + ([base] if base else []))
        for alias in node.names:
            submodule = f"{base}.{alias.name}"
            targets.add(submodule if submodule in modules else _deepest(base, modules))
    return {t for t in targets if t and t.startswith(PACKAGE) and t != name}


def import_graph(root: Path) -> Dict[str, Set[str]]:
    """module -> the package's modules it imports."""
    modules = modules_of(root)
    return {name: edges_of(name, path, modules) for name, path in modules.items()}


def folder_of(module: str) -> str:
    parts = module.split(".")
    return ".".join(parts[:2]) if len(parts) > 2 or (len(parts) == 2 and _has_children(module)) else PACKAGE


_PACKAGES: Set[str] = set()


def _has_children(module: str) -> bool:
    return module in _PACKAGES


def folder_graph(graph: Dict[str, Set[str]], root: Path) -> Dict[str, Set[str]]:
    """folder -> the folders its files import (itself left out)."""
    modules = modules_of(root)
    _PACKAGES.clear()
    _PACKAGES.update(name for name in modules if _is_package(name, modules))
    folders: Dict[str, Set[str]] = {}
    for module, targets in graph.items():
        own = folder_of(module)
        folders.setdefault(own, set()).update(folder_of(t) for t in targets if folder_of(t) != own)
    return folders


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
