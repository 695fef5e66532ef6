"""Security rules: no unsafe deserialisation, file paths stay where the user pointed, loopback by default.

The rules (docs/security.md):

* no ``pickle``/``marshal``/``dill``, ``torch.load`` without ``weights_only=True``,
  ``yaml.load``/``unsafe_load``, ``eval``/``exec``, ``shell=True``, ``os.system``
  or ``np.load(allow_pickle=True)`` anywhere in ``vmas_ros`` (checked on the AST,
  with a self-test showing the checker catches each);
* path parameters (``record_path``, ``policy_path``) are read at start only; the
  bag and its split parts go exactly to ``record_path``'s directory (no symlink
  there); a policy's ``.onnx`` sits beside its JSON, is pinned by its SHA-256 and
  may not pull data from other files;
* servers listen on 127.0.0.1 unless told otherwise.
"""
from __future__ import annotations

import ast
import inspect
import json
import math
import os
from pathlib import Path
from typing import List

import pytest

import vmas_ros
from vmas_ros.policy.onnx_policy import MAX_METADATA_BYTES, OnnxPolicy, external_tensors
from vmas_ros.ros.command import MAX_COMMAND, check_command
from vmas_ros.ros.params import PATH_PARAMETERS, RUNTIME, SIM_PARAMS, SimParams, validate

PACKAGE = Path(vmas_ros.__file__).resolve().parent


# ------------------------------------------------------------------ unsafe calls
def _dotted(node: ast.AST) -> str:
    """``a.b.c`` of a Name/Attribute chain ("" for anything else)."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Name):
        parts.append(node.id)
        return ".".join(reversed(parts))
    return ""


def _keyword(call: ast.Call, name: str):
    for keyword in call.keywords:
        if keyword.arg == name:
            return keyword.value
    return None


def _is_true(node) -> bool:
    return isinstance(node, ast.Constant) and node.value is True


UNSAFE_MODULES = {"pickle", "cPickle", "_pickle", "dill", "cloudpickle", "marshal", "shelve", "joblib"}


def unsafe_calls(source: str, filename: str = "<source>") -> List[str]:
    """Every unsafe deserialisation or shell use in ``source``, as ``file:line: what``."""
    found = []
    for node in ast.walk(ast.parse(source, filename)):
        where = f"{filename}:{getattr(node, 'lineno', 0)}"
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
            found += [f"{where}: imports {n}" for n in names if n.split(".")[0] in UNSAFE_MODULES]
        if not isinstance(node, ast.Call):
            continue
        name = _dotted(node.func)
        last = name.rsplit(".", 1)[-1]
        if name in ("eval", "exec", "compile", "__import__"):
            found.append(f"{where}: {name}()")
        elif name == "torch.load" and not _is_true(_keyword(node, "weights_only")):
            found.append(f"{where}: torch.load without weights_only=True")
        elif name.startswith("yaml.") and last in ("load", "load_all", "unsafe_load", "full_load", "unsafe_load_all"):
            found.append(f"{where}: {name} (use yaml.safe_load)")
        elif name in ("os.system", "os.popen") or name.startswith("os.exec") or name.startswith("os.spawn"):
            found.append(f"{where}: {name}")
        elif _is_true(_keyword(node, "shell")):
            found.append(f"{where}: {name} with shell=True")
        elif last == "load" and _is_true(_keyword(node, "allow_pickle")):
            found.append(f"{where}: {name} with allow_pickle=True")
        elif last in ("read_pickle", "load_pickle"):
            found.append(f"{where}: {name}")
    return found


def test_the_checker_catches_every_unsafe_pattern():
    bad = "\n".join([
        "import pickle", "from marshal import loads", "eval('1')", "exec('x = 1')",
        "torch.load(p)", "torch.load(p, weights_only=False)", "yaml.load(s, Loader=yaml.Loader)",
        "yaml.unsafe_load(s)", "subprocess.run('ls', shell=True)", "os.system('ls')",
        "np.load(p, allow_pickle=True)", "pd.read_pickle(p)",
    ])
    assert len(unsafe_calls(bad)) == 12, unsafe_calls(bad)
    good = "torch.load(p, weights_only=True)\nyaml.safe_load(s)\nsubprocess.run(['ls'])\nnp.load(p)\n"
    assert unsafe_calls(good) == []


def test_no_unsafe_deserialisation_or_shell_in_the_package():
    files = sorted(PACKAGE.rglob("*.py"))
    assert len(files) > 50, "the scan must see the whole package"
    found = [hit for path in files for hit in unsafe_calls(path.read_text(), str(path.relative_to(PACKAGE)))]
    assert found == [], "\n".join(found)


# --------------------------------------------------------------------- commands
@pytest.mark.parametrize("values, kind, named", [
    ((math.nan, 0.0, 0.0), "with NaN or inf", "linear.x=nan"),
    ((0.0, -math.inf, 0.0), "with NaN or inf", "linear.y=-inf"),
    ((0.0, 0.0, 1e30), "with huge values", "angular.z=1e+30"),
    ((1e300, 0.0, 0.0), "with huge values", "linear.x=1e+300"),  # finite, but inf in float32
])
def test_unusable_commands_are_named(values, kind, named):
    problem = check_command(values)
    assert problem is not None and problem[0] == kind and named in problem[1]
    assert f"|value| <= {MAX_COMMAND:g}" in problem[1]


def test_usable_commands_pass():
    assert check_command((0.3, -0.2, 1.5)) is None
    assert check_command((MAX_COMMAND, -MAX_COMMAND, 0)) is None


# --------------------------------------------------------------------- parameters
def test_path_parameters_cannot_change_at_runtime():
    assert set(PATH_PARAMETERS) <= set(SimParams.names())
    assert not set(PATH_PARAMETERS) & RUNTIME, "a remote set_parameters must not redirect reads or writes"
    assert not {"foxglove_host", "foxglove_port", "scenario", "device"} & RUNTIME


def test_record_path_rules(tmp_path):
    assert validate("record_path", str(tmp_path / "sub" / "run.mcap")) is None  # missing dirs are created
    assert validate("record_path", "") is None  # off
    link = tmp_path / "link.mcap"
    link.symlink_to(tmp_path / "elsewhere" / "target.mcap")  # dangling: a write would create the target
    assert "is a symlink" in validate("record_path", str(link))
    (tmp_path / "d.mcap").mkdir()
    assert "is a directory" in validate("record_path", str(tmp_path / "d.mcap"))
    assert validate("record_path", str(tmp_path / "bag")) is None  # a bag folder
    (tmp_path / "notes").write_text("not a bag")
    assert "is a file" in validate("record_path", str(tmp_path / "notes"))
    for bad in ("/", ".", "..", ".mcap", "run\0.mcap"):
        assert "record_path" in validate("record_path", bad), bad


def test_policy_path_rules(tmp_path):
    assert "end in .json or .onnx" in validate("policy_path", "/etc/passwd")
    assert "existing file" in validate("policy_path", str(tmp_path / "missing.json"))
    (tmp_path / "dir.json").mkdir()
    assert "existing file" in validate("policy_path", str(tmp_path / "dir.json"))


def test_split_bag_files_stay_in_the_given_directory(tmp_path):
    from vmas_ros.record import McapRecorder
    from geometry_msgs.msg import PoseStamped

    (tmp_path / "a").mkdir()
    given = tmp_path / "a" / ".." / "b" / "run.mcap"  # '..' is the user's own choice: resolved, not refused
    with McapRecorder(given, max_bytes=4000, chunk_size=1024, compression="none") as recorder:
        for i in range(300):
            recorder.write("/pose", "geometry_msgs/msg/PoseStamped", PoseStamped(), i * 1000)
    assert len(recorder.paths) > 1
    assert {p.resolve().parent for p in recorder.paths} == {(tmp_path / "b").resolve()}
    written = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*") if p.is_file())
    assert written == sorted(f"b/{p.name}" for p in recorder.paths)


def test_unknown_parameters_typos_fail_others_warn():
    errors, warnings = SIM_PARAMS.unknown(["num_env", "teleop_speed", "qos_overrides./clock.publisher.depth",
                                           "num_envs.a"])
    assert sorted(errors) == ["num_envs must be a single value, got a nested key 'num_envs.a'",
                              "unknown parameter 'num_env' (did you mean 'num_envs'?)"]
    assert len(warnings) == 1 and "ignores unknown parameter 'teleop_speed'" in warnings[0]


# ------------------------------------------------------------------------ policies
@pytest.fixture
def policy(tmp_path) -> Path:
    from test.ros.policy_files import constant_push

    return constant_push(tmp_path, "p", [0.1, 0.0])


def _repin(json_path: Path) -> None:
    """Update onnx_sha256 after the ONNX file was rewritten (a consistent, hostile pair)."""
    import hashlib

    meta = json.loads(json_path.read_text())
    meta["onnx_sha256"] = hashlib.sha256(json_path.with_suffix(".onnx").read_bytes()).hexdigest()
    json_path.write_text(json.dumps(meta))


def test_policy_with_external_data_is_refused_even_with_a_matching_checksum(policy):
    import onnx
    from onnx.external_data_helper import convert_model_to_external_data

    onnx_path = policy.with_suffix(".onnx")
    assert external_tensors(onnx_path.read_bytes()) == []
    OnnxPolicy.load(policy)  # loads before the change
    model = onnx.load(str(onnx_path))
    convert_model_to_external_data(model, all_tensors_to_one_file=True, location="weights.bin", size_threshold=0)
    onnx.save_model(model, str(onnx_path))
    assert (policy.parent / "weights.bin").is_file()
    _repin(policy)
    assert external_tensors(onnx_path.read_bytes()), "the scanner sees the external initializers"
    with pytest.raises(ValueError, match="keep their data in other files, which onnx_sha256 does not cover"):
        OnnxPolicy.load(policy)


def test_external_data_in_a_constant_node_is_found():
    import onnx
    from onnx import TensorProto, helper

    tensor = helper.make_tensor("c", TensorProto.FLOAT, [1], [1.0])
    tensor.ClearField("float_data")
    tensor.data_location = TensorProto.EXTERNAL
    entry = tensor.external_data.add()
    entry.key, entry.value = "location", "../../secret.bin"
    node = helper.make_node("Constant", [], ["y"], value=tensor)
    graph = helper.make_graph([node], "g", [], [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])])
    assert external_tensors(helper.make_model(graph).SerializeToString()) == ["c"]
    assert external_tensors(onnx.ModelProto().SerializeToString()) == []


def test_policy_files_that_are_not_what_they_claim(policy):
    onnx_path = policy.with_suffix(".onnx")
    onnx_path.write_bytes(b"\x0a\xff\xff\xff\xff\x0f")  # a protobuf field running past the end
    _repin(policy)
    with pytest.raises(ValueError, match="not an ONNX model"):
        OnnxPolicy.load(policy)
    policy.write_text(" " * (MAX_METADATA_BYTES + 1))
    with pytest.raises(ValueError, match="too big for policy metadata"):
        OnnxPolicy.load(policy)
    policy.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ValueError, match="not valid JSON"):
        OnnxPolicy.load(policy)


# ------------------------------------------------------------------------ servers
def test_servers_default_to_loopback():
    from vmas_ros.viz.foxglove_bridge import FoxgloveBridge

    assert SimParams().foxglove_host == "127.0.0.1"
    assert inspect.signature(FoxgloveBridge).parameters["host"].default == "127.0.0.1"
    assert "must not be empty" in validate("foxglove_host", "")
    assert os.environ.get("ROS_DOMAIN_ID"), "tests run in a domain of their own"
    assert os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") == "LOCALHOST", "tests discover DDS peers on loopback only"
