"""Full ``ros2msg`` schema text for MCAP files, built from installed ``.msg`` files.

An MCAP file of the ``ros2`` profile stores, per message type, a Schema record
with encoding ``ros2msg`` whose data is the type's ``.msg`` text followed by the
text of every message type it uses, each under a separator::

    <text of pkg/msg/Root.msg>
    ================================================================================
    MSG: pkg/Dep
    <text of pkg/msg/Dep.msg>
    ...

This is the layout rosbag2 writes; readers (``mcap-ros2-support``, ``rosbags``,
Foxglove) parse it back into a complete type. Dependencies appear once each,
depth-first in order of first use. Comments and constants stay in the text, as
rosbag2 keeps them.

The ``.msg`` files come from ``share/<pkg>/msg/<Name>.msg`` of the installation
(the ament index when ``AMENT_PREFIX_PATH`` knows the package, else
``<sys.prefix>/share/<pkg>``, which is where the ROS 2 PyPI wheels put them).
A few definitions are built in for packages that have no wheel: see
:data:`BUILTIN_DEFINITIONS`.
"""
from __future__ import annotations

import functools
import os
import re
import sys
from typing import Dict, List, Optional, Tuple

__all__ = [
    "BUILTIN_DEFINITIONS", "SEPARATOR", "dependencies", "message_definition", "msg_text", "normalize_type", "type_hash",
]

#: the line rosbag2 puts between the definitions of a schema
SEPARATOR = "=" * 80

#: ROS 2 builtin (primitive) field types; everything else names a message
PRIMITIVE_TYPES = frozenset({
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
})

#: ``.msg`` texts for message types whose package has no PyPI wheel
#: (keyed ``pkg/Name``); an installed ``.msg`` file takes precedence.
BUILTIN_DEFINITIONS: Dict[str, str] = {
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
}

# "T[]", "T[N]", "T[<=N]" after the base type
_ARRAY_SUFFIX = re.compile(r"\[(<=)?\d*\]$")
# "string<=N" / "wstring<=N"
_STRING_BOUND = re.compile(r"^(w?string)<=\d+$")
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


def normalize_type(type_name: str) -> Tuple[str, str]:
    """``pkg/msg/Name`` or ``pkg/Name`` -> ``(pkg, Name)``; ValueError otherwise."""
    parts = type_name.strip().split("/")
    if len(parts) == 3 and parts[1] == "msg":
        parts = [parts[0], parts[2]]
    if len(parts) != 2 or not all(_NAME.match(p) for p in parts):
        raise ValueError(f"not a ROS 2 message type name: {type_name!r} (expected pkg/msg/Name)")
    return parts[0], parts[1]


def _share_dirs(pkg: str) -> List[str]:
    dirs = []
    try:  # the ament index, when AMENT_PREFIX_PATH is set and knows the package
        from ament_index_python.packages import get_package_share_directory

        dirs.append(get_package_share_directory(pkg))
    except Exception:  # unset/empty AMENT_PREFIX_PATH, unknown package, no ament_index_python
        pass
    for prefix in (sys.prefix, sys.base_prefix):
        candidate = os.path.join(prefix, "share", pkg)
        if candidate not in dirs:
            dirs.append(candidate)
    return dirs


@functools.lru_cache(maxsize=None)
def msg_text(pkg: str, name: str) -> Optional[str]:
    """The text of ``pkg/msg/name.msg`` (or a built-in definition); None if unknown."""
    for share in _share_dirs(pkg):
        path = os.path.join(share, "msg", f"{name}.msg")
        if os.path.isfile(path):
            with open(path, encoding="utf-8") as f:
                return f.read()
    return BUILTIN_DEFINITIONS.get(f"{pkg}/{name}")


@functools.lru_cache(maxsize=None)
def type_hash(type_name: str) -> str:
    """The type's RIHS01 hash, as rosbag2 stores it in ``metadata.yaml``; empty if not installed.

    ROS 2 (since Iron) installs ``share/<pkg>/msg/<Name>.json`` beside the
    ``.msg`` with the type's description and hash; the built-in definitions
    (types without a wheel) have none.
    """
    import json

    try:
        pkg, name = normalize_type(type_name)
    except ValueError:
        return ""
    for share in _share_dirs(pkg):
        path = os.path.join(share, "msg", f"{name}.json")
        if os.path.isfile(path):
            try:
                with open(path, encoding="utf-8") as f:
                    hashes = json.load(f).get("type_hashes", [])
            except (OSError, ValueError, AttributeError):
                return ""
            for entry in hashes:
                if isinstance(entry, dict) and entry.get("type_name") == f"{pkg}/msg/{name}":
                    return str(entry.get("hash_string", ""))
    return ""


def _field_type(line: str) -> Optional[str]:
    """The type token of a field or constant line, None for blank and comment lines."""
    line = line.strip()
    if not line or line.startswith("#"):
        return None
    return line.split()[0]


def dependencies(pkg: str, text: str) -> List[Tuple[str, str]]:
    """Message types ``(pkg, Name)`` the fields of ``text`` use, in order of first use.

    Resolves arrays (``T[]``, ``T[N]``, ``T[<=N]``), bounded strings
    (``string<=N``), ``pkg/Name`` and ``pkg/msg/Name``, and relative names: a
    name of the same package, or ``Header`` for ``std_msgs/Header``.
    """
    found: List[Tuple[str, str]] = []
    for line in text.splitlines():
        token = _field_type(line)
        if token is None:
            continue
        base = _ARRAY_SUFFIX.sub("", token)
        if base in PRIMITIVE_TYPES or _STRING_BOUND.match(base):
            continue
        if "/" in base:
            dep = normalize_type(base)
        elif base == "Header" and msg_text(pkg, base) is None:
            dep = ("std_msgs", "Header")
        else:
            dep = (pkg, base)
            if not _NAME.match(base):
                raise ValueError(f"cannot parse field type {token!r} in a definition of package {pkg}")
        if dep not in found:
            found.append(dep)
    return found


@functools.lru_cache(maxsize=None)
def message_definition(type_name: str) -> str:
    """The full ``ros2msg`` schema text of ``type_name`` (e.g. ``sensor_msgs/msg/LaserScan``).

    The message's own ``.msg`` text comes first, then every message type it
    depends on (recursively, each once, depth-first in order of first use),
    each under a line of 80 ``=`` and ``MSG: pkg/Name``. Raises LookupError if
    the definition of the type or of one of its dependencies is not installed.
    """
    root = normalize_type(type_name)
    parts: List[str] = []
    seen = {root}

    def visit(pkg: str, name: str, path: Tuple[str, ...]) -> None:
        text = msg_text(pkg, name)
        if text is None:
            via = f" (used by {' -> '.join(path)})" if path else ""
            raise LookupError(
                f"no definition of {pkg}/msg/{name}{via}: looked for share/{pkg}/msg/{name}.msg "
                f"in {', '.join(_share_dirs(pkg))}"
            )
        if parts:
            parts.append(f"{SEPARATOR}\nMSG: {pkg}/{name}\n")
        parts.append(text.rstrip("\n") + "\n")
        for dep in dependencies(pkg, text):
            if dep not in seen:
                seen.add(dep)
                visit(*dep, path + (f"{pkg}/{name}",))

    visit(*root, ())
    return "".join(parts)
