"""launch_scripts/policy.launch.py and the policy_node console script, checked without `launch`.

`launch` and `launch_ros` have no PyPI wheels here, so the file cannot run; its
shape is checked instead: it parses, defines generate_launch_description(),
starts vmas_ros's sim_node and policy_node, and passes them only parameters
that the nodes' parameter tables know (a typo would be refused at start).
"""
from __future__ import annotations

import ast
from pathlib import Path

from vmas_ros.ros.params import PolicyNodeParams, SimParams

ROOT = Path(__file__).resolve().parents[2]
LAUNCH = ROOT / "launch_scripts" / "policy.launch.py"


def _tree() -> ast.Module:
    return ast.parse(LAUNCH.read_text())


def _node_calls(tree: ast.Module) -> dict:
    """executable -> the Node(...) call that starts it."""
    calls = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "Node":
            keywords = {k.arg: k.value for k in node.keywords}
            assert ast.literal_eval(keywords["package"]) == "vmas_ros"
            calls[ast.literal_eval(keywords["executable"])] = keywords
    return calls


def _dict_keys(tree: ast.Module, variable: str) -> set:
    """String keys of the dict literals assigned (inside a list) to ``variable``."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == variable for t in node.targets):
            return {k.value for d in ast.walk(node.value) if isinstance(d, ast.Dict) for k in d.keys
                    if isinstance(k, ast.Constant)}
    raise AssertionError(f"{variable} is not assigned in {LAUNCH.name}")


def test_launch_file_starts_sim_node_and_policy_node():
    tree = _tree()
    functions = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
    assert "generate_launch_description" in functions
    calls = _node_calls(tree)
    assert set(calls) == {"sim_node", "policy_node"}
    assert ast.literal_eval(calls["sim_node"]["name"]) == "sim_node"
    assert ast.literal_eval(calls["policy_node"]["name"]) == "policy_node"


def test_launch_file_passes_only_known_parameters():
    tree = _tree()
    sim_keys, policy_keys = _dict_keys(tree, "sim_parameters"), _dict_keys(tree, "policy_parameters")
    assert sim_keys == {"scenario", "control"} and sim_keys <= set(SimParams.names())
    assert "policy_path" in policy_keys and policy_keys <= set(PolicyNodeParams.names())
    arguments = {
        ast.literal_eval(node.args[0]) for node in ast.walk(tree)
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "DeclareLaunchArgument"
    }
    assert {"scenario", "config"} | policy_keys <= arguments


def test_policy_node_console_script_is_declared():
    source = (ROOT / "setup.py").read_text()
    assert '"policy_node = vmas_ros.ros.startup:policy_node_main",' in source
