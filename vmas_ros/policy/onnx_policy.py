"""Load and run a policy exported by ``vmas-ros export`` (``<stem>.onnx`` + ``<stem>.json``).

This module only needs numpy and onnxruntime (never torch): a robot or a ROS node
running a trained policy should not have to install a training stack.

The export contract (written by ``vmas_ros.train.export``):

* ``<stem>.onnx``: one input ``"observation"``, float32 ``[batch, n_agents, obs_size]``
  (dynamic batch); one output ``"action"``, float32 ``[batch, n_agents, action_size]``,
  the deterministic action already clipped to the action bounds;
* ``<stem>.json``: the metadata checked by :func:`validate_metadata`; its
  ``onnx_sha256`` ties it to exactly one ``.onnx`` file, which must keep all
  its weights inside (no external data files, which no checksum covers) and
  sit beside the JSON (``onnx_file`` is a bare file name).

Every check raises ``ValueError`` naming the bad value and what was expected, so a
mismatched or tampered pair of files fails at load time, not mid-mission.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import re
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple, Union

import numpy as np

from vmas_ros.policy.protobuf_wire import ProtobufFormatError, read_fields

__all__ = ["OnnxPolicy", "read_metadata", "validate_metadata", "POLICY_FORMAT", "POLICY_VERSION", "sha256_of_file",
           "external_tensors"]

#: value of the metadata's "format" key
POLICY_FORMAT = "vmas_ros.policy"
#: the only metadata version this reader understands
POLICY_VERSION = 1
INPUT_NAME = "observation"
OUTPUT_NAME = "action"
#: a policy's metadata is a few hundred bytes; a bigger file is not one (and is not read into memory)
MAX_METADATA_BYTES = 1 << 20

# key -> (expected python types, description used in error messages)
_REQUIRED_KEYS: Dict[str, tuple] = {
    "format": (str, "a string"),
    "version": (int, "an int"),
    "scenario": (str, "a string"),
    "scenario_kwargs": (dict, "a JSON object"),
    "algorithm": (str, "a string"),
    "agents": (list, "a list of agent names"),
    "observation_size": (int, "an int"),
    "action_size": (int, "an int"),
    "action_low": (list, "a list of numbers"),
    "action_high": (list, "a list of numbers"),
    "action_type": (str, "a string"),
    "onnx_file": (str, "a string"),
    "onnx_sha256": (str, "a string"),
    "created_by": (str, "a string"),
}


def sha256_of_file(path: Union[str, Path]) -> str:
    """Hex SHA-256 of a file, read in chunks (policies can be tens of MB)."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def validate_metadata(meta: Any, source: str = "policy metadata") -> Dict[str, Any]:
    """Check the metadata dict's keys, types and values; return it unchanged.

    Raises ``ValueError`` naming the key, the bad value and what was expected.
    """
    if not isinstance(meta, dict):
        raise ValueError(f"{source}: expected a JSON object, got {type(meta).__name__}")
    missing = [key for key in _REQUIRED_KEYS if key not in meta]
    if missing:
        raise ValueError(f"{source}: missing key(s) {missing}; expected all of {list(_REQUIRED_KEYS)}")
    for key, (kind, what) in _REQUIRED_KEYS.items():
        value = meta[key]
        # bool is an int in Python, but True is no version or size
        if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
            raise ValueError(f"{source}: {key!r} must be {what}, got {value!r} ({type(value).__name__})")
    if meta["format"] != POLICY_FORMAT:
        raise ValueError(f"{source}: 'format' is {meta['format']!r}, expected {POLICY_FORMAT!r}")
    if meta["version"] != POLICY_VERSION:
        raise ValueError(f"{source}: unsupported 'version' {meta['version']!r}, this reader understands {POLICY_VERSION}")
    if meta["action_type"] != "continuous":
        raise ValueError(f"{source}: 'action_type' is {meta['action_type']!r}, expected 'continuous'")
    agents = meta["agents"]
    if not agents or not all(isinstance(name, str) and name for name in agents):
        raise ValueError(f"{source}: 'agents' must be a non-empty list of non-empty strings, got {agents!r}")
    if len(set(agents)) != len(agents):
        raise ValueError(f"{source}: 'agents' has duplicate names: {agents!r}")
    for key in ("observation_size", "action_size"):
        if meta[key] < 1:
            raise ValueError(f"{source}: {key!r} must be >= 1, got {meta[key]!r}")
    for key in ("action_low", "action_high"):
        bounds = meta[key]
        if len(bounds) != meta["action_size"]:
            raise ValueError(f"{source}: {key!r} has {len(bounds)} values, expected action_size={meta['action_size']}")
        bad = [b for b in bounds if not _is_number(b)]
        if bad:
            raise ValueError(f"{source}: {key!r} must hold finite numbers, got {bad!r}")
    inverted = [i for i, (lo, hi) in enumerate(zip(meta["action_low"], meta["action_high"])) if lo > hi]
    if inverted:
        raise ValueError(f"{source}: action_low > action_high at index(es) {inverted}: "
                         f"low={meta['action_low']}, high={meta['action_high']}")
    onnx_file = meta["onnx_file"]
    if not onnx_file.endswith(".onnx") or os.path.basename(onnx_file) != onnx_file:
        raise ValueError(f"{source}: 'onnx_file' must be a bare file name ending in .onnx, got {onnx_file!r}")
    if not re.fullmatch(r"[0-9a-f]{64}", meta["onnx_sha256"]):
        raise ValueError(f"{source}: 'onnx_sha256' must be 64 lowercase hex digits, got {meta['onnx_sha256']!r}")
    return meta


def read_metadata(path: Union[str, Path]) -> Tuple[Path, Dict[str, Any]]:
    """``(<stem>.json, its checked metadata)`` of the policy at ``path`` (either file of the pair).

    Reads only the JSON (no ONNX, no onnxruntime), so a caller may learn the
    policy's scenario before anything is built; raises ``ValueError`` naming
    the file and what is wrong with it.
    """
    path = Path(path)
    if path.suffix == ".json":
        json_path = path
    elif path.suffix == ".onnx":
        json_path = path.with_suffix(".json")
    else:
        raise ValueError(f"policy path must end in .json or .onnx, got {str(path)!r}")
    if not json_path.is_file():
        raise ValueError(f"policy metadata file {str(json_path)!r} does not exist")
    size = json_path.stat().st_size
    if size > MAX_METADATA_BYTES:
        raise ValueError(f"{json_path}: {size} bytes is too big for policy metadata "
                         f"(at most {MAX_METADATA_BYTES}); is it the right file?")
    try:
        meta = json.loads(json_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as error:
        raise ValueError(f"{json_path}: not valid JSON: {error}") from error
    return json_path, validate_metadata(meta, source=str(json_path))


# ------------------------------------------------------------------ external data
# A tensor may keep its data in another file (``data_location = EXTERNAL`` plus a
# ``location`` path), which onnxruntime reads from the model's directory, or from
# the working directory for a model loaded from bytes. No checksum covers those
# bytes, and ``vmas-ros export`` never writes them, so such models are refused.
# The protobuf wire format is walked here directly (field numbers of onnx.proto,
# stable since IR version 3): this module must run without the onnx package and
# be loadable on its own (no other vmas_ros import, which would pull in torch).

# ModelProto
_MODEL_GRAPH, _MODEL_FUNCTIONS = 7, 25
# GraphProto
_GRAPH_NODE, _GRAPH_INITIALIZER, _GRAPH_SPARSE_INITIALIZER = 1, 5, 15
# NodeProto / FunctionProto
_NODE_ATTRIBUTE, _FUNCTION_NODE = 5, 7
# AttributeProto: t, g, tensors, graphs, sparse_tensor, sparse_tensors
_ATTR_T, _ATTR_G, _ATTR_TENSORS, _ATTR_GRAPHS, _ATTR_SPARSE, _ATTR_SPARSES = 5, 6, 10, 11, 22, 23
# SparseTensorProto: values, indices
_SPARSE_VALUES, _SPARSE_INDICES = 1, 2
# TensorProto
_TENSOR_NAME, _TENSOR_EXTERNAL_DATA, _TENSOR_DATA_LOCATION = 8, 13, 14
_EXTERNAL = 1
_MAX_DEPTH = 64  # subgraphs nest (If/Loop bodies); deeper is malformed or hostile


def _tensor(data: bytes, found: List[str]) -> None:
    name, external = "", False
    for number, wire, value in read_fields(data):
        if number == _TENSOR_NAME and wire == 2:
            name = bytes(value).decode("utf-8", "replace")
        elif number == _TENSOR_DATA_LOCATION and wire == 0 and value == _EXTERNAL:
            external = True
        elif number == _TENSOR_EXTERNAL_DATA and wire == 2:
            external = True
    if external:
        found.append(name or "<unnamed>")


def _sparse(data: bytes, found: List[str]) -> None:
    for number, wire, value in read_fields(data):
        if number in (_SPARSE_VALUES, _SPARSE_INDICES) and wire == 2:
            _tensor(value, found)


def _node(data: bytes, found: List[str], depth: int) -> None:
    for number, wire, attribute in read_fields(data):
        if number != _NODE_ATTRIBUTE or wire != 2:
            continue
        for field, kind, value in read_fields(attribute):
            if kind != 2:
                continue
            if field in (_ATTR_T, _ATTR_TENSORS):
                _tensor(value, found)
            elif field in (_ATTR_G, _ATTR_GRAPHS):
                _graph(value, found, depth + 1)
            elif field in (_ATTR_SPARSE, _ATTR_SPARSES):
                _sparse(value, found)


def _graph(data: bytes, found: List[str], depth: int) -> None:
    if depth > _MAX_DEPTH:
        raise ProtobufFormatError(f"subgraphs nested deeper than {_MAX_DEPTH}")
    for number, wire, value in read_fields(data):
        if wire != 2:
            continue
        if number == _GRAPH_INITIALIZER:
            _tensor(value, found)
        elif number == _GRAPH_SPARSE_INITIALIZER:
            _sparse(value, found)
        elif number == _GRAPH_NODE:
            _node(value, found, depth)


def external_tensors(model: bytes) -> List[str]:
    """Names of every tensor in the serialised ModelProto whose data lives in another file.

    Raises :class:`ProtobufFormatError` when the bytes are not a protobuf message.
    """
    found: List[str] = []
    data = memoryview(model).tobytes() if not isinstance(model, bytes) else model
    for number, wire, value in read_fields(data):
        if wire != 2:
            continue
        if number == _MODEL_GRAPH:
            _graph(value, found, 0)
        elif number == _MODEL_FUNCTIONS:
            for field, kind, node in read_fields(value):
                if field == _FUNCTION_NODE and kind == 2:
                    _node(node, found, 0)
    return found


def _dims(value_info) -> List[Optional[int]]:
    """An onnxruntime NodeArg's shape, with symbolic (dynamic) dims as None."""
    return [dim if isinstance(dim, int) else None for dim in value_info.shape]


class OnnxPolicy:
    """A trained multi-agent policy: ``act(observation) -> action`` on numpy arrays.

    Build it with :meth:`load`; the constructor expects metadata and a session
    that were already checked against each other.
    """

    def __init__(self, metadata: Dict[str, Any], session: Any, onnx_path: Path) -> None:
        self.metadata = metadata
        self.session = session
        self.onnx_path = onnx_path
        self.agents: List[str] = list(metadata["agents"])
        self.n_agents = len(self.agents)
        self.observation_size: int = metadata["observation_size"]
        self.action_size: int = metadata["action_size"]
        self.action_low = np.asarray(metadata["action_low"], dtype=np.float32)
        self.action_high = np.asarray(metadata["action_high"], dtype=np.float32)
        self.scenario: str = metadata["scenario"]
        self.algorithm: str = metadata["algorithm"]

    # ------------------------------------------------------------------ loading
    @classmethod
    def load(cls, path: Union[str, Path], providers: Optional[List[str]] = None) -> "OnnxPolicy":
        """Load ``<stem>.json`` + ``<stem>.onnx`` given either file's path.

        Validates the metadata, the ONNX file's SHA-256 against it, and the ONNX
        graph's input/output names and sizes against the metadata.
        """
        import onnxruntime as ort

        path = Path(path)
        json_path, meta = read_metadata(path)
        onnx_path = json_path.parent / meta["onnx_file"]
        if path.suffix == ".onnx" and onnx_path.resolve() != path.resolve():
            raise ValueError(f"{json_path}: 'onnx_file' is {meta['onnx_file']!r}, expected {path.name!r}")
        if not onnx_path.is_file():
            raise ValueError(f"{json_path}: ONNX file {str(onnx_path)!r} (from 'onnx_file') does not exist")
        # read once: the bytes that are hashed are the bytes onnxruntime loads (no swap in between)
        model = onnx_path.read_bytes()
        digest = hashlib.sha256(model).hexdigest()
        if digest != meta["onnx_sha256"]:
            raise ValueError(f"{onnx_path}: SHA-256 is {digest}, but {json_path.name} expects {meta['onnx_sha256']} "
                             "(the ONNX file was modified or belongs to another export)")
        try:
            external = external_tensors(model)
        except ProtobufFormatError as error:
            raise ValueError(f"{onnx_path}: not an ONNX model ({error})") from error
        if external:
            raise ValueError(f"{onnx_path}: tensors {external[:5]} keep their data in other files, which "
                             f"onnx_sha256 does not cover; export the policy with its weights inside the .onnx")
        try:
            session = ort.InferenceSession(model, providers=providers or ["CPUExecutionProvider"])
        except Exception as error:  # onnxruntime raises its own exception types
            raise ValueError(f"{onnx_path}: onnxruntime cannot load it: {error}") from error
        cls._check_graph(session, meta, onnx_path)
        return cls(meta, session, onnx_path)

    @staticmethod
    def _check_graph(session: Any, meta: Dict[str, Any], onnx_path: Path) -> None:
        n_agents = len(meta["agents"])
        for kind, nodes, name, size_key in (
            ("input", session.get_inputs(), INPUT_NAME, "observation_size"),
            ("output", session.get_outputs(), OUTPUT_NAME, "action_size"),
        ):
            names = [node.name for node in nodes]
            if names != [name]:
                raise ValueError(f"{onnx_path}: ONNX {kind}s are {names}, expected exactly [{name!r}]")
            node = nodes[0]
            if node.type != "tensor(float)":
                raise ValueError(f"{onnx_path}: ONNX {kind} {name!r} has type {node.type}, expected tensor(float)")
            dims = _dims(node)
            expected = [None, n_agents, meta[size_key]]
            if len(dims) != 3 or dims[1:] != expected[1:]:
                raise ValueError(f"{onnx_path}: ONNX {kind} {name!r} has shape {node.shape}, expected "
                                 f"[batch, {n_agents} (agents), {meta[size_key]} ({size_key})]")

    # ------------------------------------------------------------------- acting
    def act(self, observation: np.ndarray) -> np.ndarray:
        """Deterministic actions for ``observation`` [B, n_agents, obs] (or [n_agents, obs]).

        Returns float32 [B, n_agents, action_size] (or [n_agents, action_size]),
        within ``[action_low, action_high]``.
        """
        obs = np.asarray(observation)
        if obs.dtype == object or not (np.issubdtype(obs.dtype, np.floating) or np.issubdtype(obs.dtype, np.integer)):
            raise ValueError(f"observation must be a numeric array, got dtype {obs.dtype}")
        single = obs.ndim == 2
        if single:
            obs = obs[None]
        expected = (self.n_agents, self.observation_size)
        if obs.ndim != 3 or tuple(obs.shape[1:]) != expected:
            raise ValueError(f"observation has shape {tuple(np.shape(observation))}, expected "
                             f"[batch, {self.n_agents}, {self.observation_size}] or [{self.n_agents}, "
                             f"{self.observation_size}] (agents {self.agents})")
        if obs.shape[0] == 0:
            raise ValueError("observation has an empty batch (shape[0] == 0)")
        obs = np.ascontiguousarray(obs, dtype=np.float32)
        if not np.isfinite(obs).all():
            raise ValueError("observation contains NaN or inf")
        (action,) = self.session.run([OUTPUT_NAME], {INPUT_NAME: obs})
        action = np.clip(action, self.action_low, self.action_high).astype(np.float32, copy=False)
        return action[0] if single else action

    def __repr__(self) -> str:
        return (f"OnnxPolicy({self.scenario!r}, {self.algorithm!r}, agents={self.agents}, "
                f"obs={self.observation_size}, act={self.action_size})")
