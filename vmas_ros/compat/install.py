"""``install_as_vmas()``: the name ``vmas`` resolves to vmas_ros, for code written for VMAS 1.5.

After one call, ``import vmas`` gives a small top-level module and every
``vmas.X.Y`` gives the module ``vmas_ros.X.Y`` itself: the same object, found
by the same relative path, with no table in between. A real VMAS installed
beside vmas_ros is shadowed: none of its modules is read or run.

Why ``vmas`` is not the ``vmas_ros`` package object itself: ``vmas.__version__``
must say which VMAS release we are compatible with ("1.5.2", what TorchRL and
BenchMARL read), while ``vmas_ros.__version__`` stays our own. So the top level
is a module of its own that holds no code: it carries the two versions and hands
every other name on to ``vmas_ros`` (``vmas.make_env is vmas_ros.make_env``).
Every module below it is vmas_ros's, never a second copy, so classes, isinstance
checks and pickles agree whichever name a caller used.

Nothing here imports torch: the aliased modules load when first imported.
"""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import types
import warnings
from typing import Optional

__all__ = ["VMAS_VERSION", "install_as_vmas", "is_installed", "gym_spaces_enabled"]

#: the VMAS release whose API vmas_ros follows: ``vmas.__version__`` while installed
VMAS_VERSION = "1.5.2"

_ALIAS = "vmas"
_TARGET = "vmas_ros"
#: libraries that look for ``vmas`` when they are imported (TorchRL: ``torchrl.envs.libs.vmas._has_vmas``)
_MUST_COME_AFTER = ("torchrl", "benchmarl")


class _VmasPackage(types.ModuleType):
    """The top-level ``vmas`` module: VMAS's version, and every other name vmas_ros's."""

    def __getattr__(self, name: str):
        try:
            return getattr(importlib.import_module(_TARGET), name)
        except AttributeError:
            raise AttributeError(f"module 'vmas' (an alias of vmas_ros) has no attribute {name!r}") from None

    def __setattr__(self, name: str, value) -> None:
        # The import system binds each imported submodule ``vmas.X`` onto this module. Leave
        # that name to vmas_ros, which may bind something else to it (``vmas.make_env`` is the
        # function, though a module ``vmas.make_env`` may exist too).
        if isinstance(value, types.ModuleType) and value.__name__ == f"{_TARGET}.{name}":
            return
        super().__setattr__(name, value)

    def __dir__(self):
        return sorted(set(super().__dir__()) | set(dir(importlib.import_module(_TARGET))))


class _AliasLoader(importlib.abc.Loader):
    """Loads an alias name by handing back an already imported module, unchanged."""

    def __init__(self, module: types.ModuleType, own_spec: Optional[importlib.machinery.ModuleSpec] = None) -> None:
        self._module = module
        self._own_spec = own_spec if own_spec is not None else module.__spec__

    def create_module(self, spec):
        return self._module

    def exec_module(self, module) -> None:
        # importlib has just set ``__spec__`` to the alias's spec (the only attribute it
        # overwrites on an existing module): give the module its own back
        module.__spec__ = self._own_spec


class _AliasFinder(importlib.abc.MetaPathFinder):
    """Resolves ``vmas`` and ``vmas.X.Y`` to ``vmas_ros`` and ``vmas_ros.X.Y``; first on ``sys.meta_path``."""

    def __init__(self, package: _VmasPackage) -> None:
        self.package = package

    def find_spec(self, fullname: str, path=None, target=None):
        if fullname == _ALIAS:  # only when someone dropped it from sys.modules
            return self.package.__spec__
        if not fullname.startswith(_ALIAS + "."):
            return None
        twin = _TARGET + fullname[len(_ALIAS):]
        try:
            module = importlib.import_module(twin)
        except ModuleNotFoundError as error:
            if error.name == twin or (error.name and twin.startswith(error.name + ".")):
                raise ModuleNotFoundError(
                    f"No module named {fullname!r}: vmas_ros.install_as_vmas() resolves it to {twin!r}, "
                    f"which does not exist", name=fullname,
                ) from None
            raise  # the twin exists but one of its own imports is missing
        return importlib.machinery.ModuleSpec(fullname, _AliasLoader(module), is_package=hasattr(module, "__path__"))


_finder: Optional[_AliasFinder] = None
_gym_found = False


def is_installed() -> bool:
    """Whether :func:`install_as_vmas` is in effect in this process."""
    return _finder is not None and _finder in sys.meta_path


def gym_spaces_enabled() -> bool:
    """Whether Environments build legacy ``gym`` spaces: installed, and ``gym`` importable."""
    return _gym_found and is_installed()


def _imported_vmas() -> list:
    return sorted(
        name for name, module in list(sys.modules.items())  # a copy: other threads may import meanwhile
        if module is not None and (name == _ALIAS or name.startswith(_ALIAS + "."))
    )


def _refuse_if_too_late() -> None:
    imported = _imported_vmas()
    if imported:
        where = getattr(sys.modules[imported[0]], "__file__", None)
        raise RuntimeError(
            f"install_as_vmas() must run before VMAS is imported, but {imported[0]!r} is already imported "
            f"(from {where}): call it before anything imports vmas"
        )
    early = [name for name in _MUST_COME_AFTER if name in sys.modules]
    if early:
        raise RuntimeError(
            f"install_as_vmas() must run before {' and '.join(early)} is imported (it looks for vmas when "
            f"imported), but it already is: call install_as_vmas() first, at the top of the script"
        )


def _make_package(vmas_ros: types.ModuleType) -> _VmasPackage:
    package = _VmasPackage(_ALIAS, "vmas_ros standing in for VMAS (see vmas_ros.install_as_vmas).")
    spec = importlib.machinery.ModuleSpec(_ALIAS, None, origin=vmas_ros.__spec__.origin, is_package=True)
    spec.loader = _AliasLoader(package, own_spec=spec)
    spec.submodule_search_locations = list(vmas_ros.__path__)
    package.__spec__ = spec
    package.__loader__ = spec.loader
    package.__path__ = spec.submodule_search_locations  # pkgutil.iter_modules(vmas.__path__) lists ours
    package.__file__ = vmas_ros.__file__
    package.__version__ = VMAS_VERSION
    package.vmas_ros_version = vmas_ros.__version__
    package.__all__ = list(vmas_ros.__all__)
    return package


def install_as_vmas() -> types.ModuleType:
    """Make ``import vmas`` and every ``vmas.X.Y`` resolve to vmas_ros, for this process.

    Call it first thing, before anything imports ``vmas``, ``torchrl`` or
    ``benchmarl``::

        import vmas_ros
        vmas_ros.install_as_vmas()
        from torchrl.envs.libs.vmas import VmasEnv  # now builds vmas_ros environments

    - ``vmas.X.Y`` is the module ``vmas_ros.X.Y`` itself (found by the same
      relative path; a path with no twin raises ``ModuleNotFoundError`` naming
      both). A real ``vmas`` installed beside vmas_ros is shadowed, never imported.
    - ``vmas.__version__`` is :data:`VMAS_VERSION`; vmas_ros's own version is
      ``vmas.vmas_ros_version`` (and ``vmas_ros.__version__``).
    - While installed, Environments build legacy ``gym`` spaces, as VMAS does:
      TorchRL's ``VmasEnv`` converts spaces with its ``gym`` backend and refuses
      gymnasium ones. ``gym`` is the optional extra ``vmas_ros[gym]``; without
      it this warns and spaces stay gymnasium. Without ``install_as_vmas()``
      spaces are always gymnasium.
    - A second call does nothing. There is no uninstall: modules imported
      under either name would keep the other name's behaviour.

    Returns:
        the ``vmas`` module.

    Raises:
        RuntimeError: a real ``vmas`` module, ``torchrl`` or ``benchmarl`` is
            already imported. TorchRL decides whether VMAS exists when it is
            imported, so aliasing afterwards would half work (only when a real
            VMAS is installed too): an error at the call names the fix, where
            a warning would leave a failure later, far from its cause.
    """
    global _finder, _gym_found
    if is_installed():
        return sys.modules.get(_ALIAS) or importlib.import_module(_ALIAS)
    _refuse_if_too_late()
    vmas_ros = importlib.import_module(_TARGET)
    package = _make_package(vmas_ros)
    _gym_found = importlib.util.find_spec("gym") is not None
    if not _gym_found:
        warnings.warn(
            "install_as_vmas(): legacy `gym` is not installed (pip install 'vmas_ros[gym]'), so Environments "
            "keep gymnasium spaces and TorchRL's VmasEnv will refuse them", RuntimeWarning, stacklevel=2,
        )
    _finder = _AliasFinder(package)
    sys.meta_path.insert(0, _finder)
    sys.modules[_ALIAS] = package
    return package
