"""Public names of a VMAS module against vmas_ros's module at the same path.

A module's public surface is its module-level names that do not start with
``_``, leaving out modules (imported libraries). For each public class it adds
the class's public attributes (methods, properties, class constants), and for
every function or method its parameters: name, kind and default. The result is
a set of strings such as ``"vmas.make_env: make_env(scenario, ...)"`` so that a
difference reads as one line.

VMAS modules that cannot be imported here (one needs an X display, two need
``shimmy``, one ``wandb``) are read from their source with ``ast`` instead: then
only module-level and class-level names are compared, not signatures.
"""
from __future__ import annotations

import ast
import enum
import importlib
import inspect
import types
from pathlib import Path
from typing import Iterable, Optional, Set, Tuple

#: the VMAS 1.5.2 modules (scenarios aside, which have their own parity tests); VMAS path -> vmas_ros path
VMAS_MODULES = [
    "vmas", "vmas.examples", "vmas.examples.rllib", "vmas.examples.run_heuristic", "vmas.examples.use_vmas_env",
    "vmas.interactive_rendering", "vmas.make_env",
    "vmas.simulator", "vmas.simulator.core", "vmas.simulator.heuristic_policy", "vmas.simulator.joints",
    "vmas.simulator.physics", "vmas.simulator.rendering", "vmas.simulator.scenario", "vmas.simulator.sensors",
    "vmas.simulator.utils",
    "vmas.simulator.controllers", "vmas.simulator.controllers.velocity_controller",
    "vmas.simulator.dynamics", "vmas.simulator.dynamics.common", "vmas.simulator.dynamics.diff_drive",
    "vmas.simulator.dynamics.drone", "vmas.simulator.dynamics.forward", "vmas.simulator.dynamics.holonomic",
    "vmas.simulator.dynamics.holonomic_with_rot", "vmas.simulator.dynamics.kinematic_bicycle",
    "vmas.simulator.dynamics.roatation", "vmas.simulator.dynamics.static",
    "vmas.simulator.environment", "vmas.simulator.environment.environment", "vmas.simulator.environment.rllib",
    "vmas.simulator.environment.gym", "vmas.simulator.environment.gym.base", "vmas.simulator.environment.gym.gym",
    "vmas.simulator.environment.gym.gymnasium", "vmas.simulator.environment.gym.gymnasium_vec",
]


def ours(vmas_path: str) -> str:
    """The vmas_ros module path for a VMAS one: the same relative path."""
    return "vmas_ros" + vmas_path[len("vmas"):]


def _default_text(value) -> str:
    """A default as comparable text: an enum member by class and name (VMAS's ``Color`` and ours are
    different classes with equal members), a function or lambda by kind only (its repr holds an address),
    a class by name, a number by value."""
    if isinstance(value, enum.Enum):
        return f"{type(value).__name__}.{value.name}"
    if inspect.isfunction(value) or inspect.isbuiltin(value):
        return "<function>"
    if inspect.isclass(value):
        return f"<class {value.__name__}>"  # VMAS's RandomPolicy and ours
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return repr(float(value))  # 100 and 100.0 are the same default
    return repr(value)


def _describe_callable(prefix: str, obj) -> str:
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return f"{prefix}(?)"
    parts = []
    for p in sig.parameters.values():
        text = f"{p.name}:{p.kind.name}"
        if p.default is not inspect.Parameter.empty:
            text += f"={_default_text(p.default)}"
        parts.append(text)
    return f"{prefix}({', '.join(parts)})"


def _class_surface(prefix: str, cls: type) -> Iterable[str]:
    yield prefix
    for name in sorted(dir(cls)):
        if name.startswith("_") and name != "__init__":
            continue
        try:
            attr = inspect.getattr_static(cls, name)
        except AttributeError:
            continue
        if isinstance(attr, (staticmethod, classmethod)):
            attr = attr.__func__
        if isinstance(attr, property):
            yield f"{prefix}.{name}: property"
        elif inspect.isfunction(attr):
            # a method inherited from a third-party base (gym.Env, Enum) is that library's, not ours
            owner = getattr(attr, "__module__", "") or ""
            if owner.split(".")[0] in ("vmas", "vmas_ros"):
                yield _describe_callable(f"{prefix}.{name}", attr)
        elif not callable(attr) and not isinstance(attr, types.MemberDescriptorType):
            yield f"{prefix}.{name}: attribute"


def _is_own(obj) -> bool:
    """Whether a module-level object belongs to VMAS or vmas_ros (not an imported library's, like ``torch``)."""
    if isinstance(obj, (bool, int, float, str, tuple, list, dict)) or obj is None:
        return True
    return (getattr(obj, "__module__", None) or "").split(".")[0] in ("vmas", "vmas_ros")


def runtime_surface(
    module: types.ModuleType, label: str, expand: Optional[Set[str]] = None, wanted: Iterable[str] = (),
) -> Set[str]:
    """The public surface of an imported module, each line prefixed by ``label`` (the VMAS path).

    Classes and functions are described in full only where VMAS defines them
    (``expand``, by default those whose ``__module__`` is this module); a name
    the module merely imports from a sibling is listed by name.
    """
    out = set()
    # __all__ and ``wanted`` (VMAS's names): names a module loads lazily through ``__getattr__``
    names = set(dir(module)) | set(getattr(module, "__all__", ())) | {n for n in wanted if hasattr(module, n)}
    for name in sorted(n for n in names if not n.startswith("_")):
        obj = getattr(module, name, None)
        if isinstance(obj, types.ModuleType) or not _is_own(obj):
            continue
        prefix = f"{label}: {name}"
        home = name in expand if expand is not None else getattr(obj, "__module__", None) == module.__name__
        if inspect.isclass(obj) and home:
            out.update(_class_surface(prefix, obj))
        elif inspect.isfunction(obj) and home:
            out.add(_describe_callable(prefix, obj))
        else:
            out.add(prefix)
    return out


def home_names(module: types.ModuleType) -> Set[str]:
    """Names of the classes and functions ``module`` itself defines."""
    return {n for n, o in vars(module).items() if getattr(o, "__module__", None) == module.__name__}


def source_surface(path: Path, label: str) -> Set[str]:
    """Module-level and class-level public names of a VMAS module read from its source (no signatures)."""
    tree = ast.parse(path.read_text())
    out = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and not node.name.startswith("_"):
            out.add(f"{label}: {node.name}")
            if isinstance(node, ast.ClassDef):
                for item in node.body:
                    if isinstance(item, ast.FunctionDef) and not item.name.startswith("_"):
                        out.add(f"{label}: {node.name}.{item.name}")
        elif isinstance(node, ast.Assign):
            out.update(f"{label}: {t.id}" for t in node.targets if isinstance(t, ast.Name) and not t.id.startswith("_"))
    return out


def names_only(surface: Set[str]) -> Set[str]:
    """A surface reduced to what :func:`source_surface` can see: names, no signatures or kinds."""
    return {line.split("(")[0].split(": property")[0].split(": attribute")[0] for line in surface}


def vmas_surface(vmas_path: str) -> Tuple[Set[str], Optional[Set[str]]]:
    """``(surface, homes)``: the installed VMAS module's surface and the names it defines (None: read from source)."""
    try:
        module = importlib.import_module(vmas_path)
        return runtime_surface(module, vmas_path), home_names(module)
    except Exception:  # noqa: BLE001 - any import failure (no display, no shimmy, no wandb) falls back to the source
        vmas_root = Path(importlib.util.find_spec("vmas").origin).parent
        rel = vmas_path.split(".")[1:]
        file = vmas_root.joinpath(*rel).with_suffix(".py")
        if not file.exists():
            file = vmas_root.joinpath(*rel, "__init__.py")
        return source_surface(file, vmas_path), None


def ours_surface(vmas_path: str, homes: Optional[Set[str]], wanted: Iterable[str] = ()) -> Set[str]:
    """vmas_ros's surface at the same path, labelled with the VMAS path so the two compare line by line.

    ``homes``: the names VMAS defines in this module, described in full on our side too
    (ours may define them elsewhere and re-export them here); None gives names only.
    """
    if homes is not None:
        return runtime_surface(importlib.import_module(ours(vmas_path)), vmas_path, homes, wanted)
    module = importlib.import_module(ours(vmas_path))
    return names_only(runtime_surface(module, vmas_path, {n for n in dir(module) if not n.startswith("_")}, wanted))


def top_names(surface: Set[str]) -> Set[str]:
    """Module-level names in a surface (``"vmas.x: Name.attr(...)"`` -> ``"Name"``)."""
    return {line.split(": ", 1)[1].split(".")[0].split("(")[0].split(":")[0] for line in surface}


def missing(vmas_path: str) -> Set[str]:
    """Lines of VMAS's surface at ``vmas_path`` that vmas_ros's module at the same path lacks or spells differently."""
    theirs, homes = vmas_surface(vmas_path)
    return theirs - ours_surface(vmas_path, homes, top_names(theirs))


def vmas_scenario_modules() -> list:
    """Every module of VMAS 1.5.2's ``vmas.scenarios`` package (found on disk, not imported)."""
    import importlib.util
    import pkgutil

    spec = importlib.util.find_spec("vmas.scenarios")
    if spec is None:
        return []
    return sorted(module.name for module in pkgutil.walk_packages(spec.submodule_search_locations, "vmas.scenarios."))


def module_level_names(vmas_path: str) -> Set[str]:
    """The public names a VMAS module defines itself (functions, classes, assignments at module level), read
    from its source: what it imports for its own use is not its surface."""
    import importlib.util

    origin = importlib.util.find_spec(vmas_path).origin
    names: Set[str] = set()
    for node in ast.parse(Path(origin).read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names.update(target.id for target in node.targets if isinstance(target, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return {name for name in names if not name.startswith("_")}


def missing_module_names(vmas_path: str) -> Set[str]:
    """``"<vmas path>: <name>"`` for each name of :func:`module_level_names` that vmas_ros's module lacks."""
    module = importlib.import_module(ours(vmas_path))
    return {f"{vmas_path}: {name}" for name in module_level_names(vmas_path) if not hasattr(module, name)}
