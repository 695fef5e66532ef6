"""The fleet stays off the engine, starts from every entry point, and docs/fleet.md matches its table."""
from __future__ import annotations

import ast
import math
import re
import subprocess
import sys
from pathlib import Path
from typing import Dict, List

import pytest

from vmas_ros.fleet.params import FLEET_PARAMS, FleetParams

ROOT = Path(__file__).resolve().parents[2]
FLEET = ROOT / "vmas_ros" / "fleet"
DOC = ROOT / "docs" / "fleet.md"
#: what the fleet must never load: torch and vmas_ros's engine
ENGINE = ("torch", "vmas_ros.simulator", "vmas_ros.scenarios", "vmas_ros.envs", "vmas_ros.make_env")
#: the only vmas_ros modules outside the fleet it may use (no torch in them)
ALLOWED = {"vmas_ros.ros.param_table", "vmas_ros.ros.lifecycle", "vmas_ros.ros.signal_guard",
           "vmas_ros.ros.topic_audit"}


def imported_modules(path: Path) -> List[str]:
    names = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.append(node.module)
    return names


@pytest.mark.parametrize("path", sorted(FLEET.glob("*.py")), ids=lambda p: p.name)
def test_no_fleet_module_imports_the_engine(path):
    for name in imported_modules(path):
        assert not name.startswith(ENGINE), f"{path.name} imports {name}"
        if name.startswith("vmas_ros.") and not name.startswith("vmas_ros.fleet"):
            assert name in ALLOWED, f"{path.name} imports {name}"
    assert len(path.read_text().splitlines()) <= 450, f"{path.name} is over 450 lines"


def test_importing_the_node_loads_neither_torch_nor_the_engine():
    code = ("import sys, vmas_ros.fleet.node\n"
            "print('\\n'.join(sorted(sys.modules)))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                            check=True).stdout.split()
    assert "rclpy" in loaded and "vmas_ros.fleet.world" in loaded
    assert "torch" not in loaded
    engine = [m for m in loaded if m.startswith(("vmas_ros.simulator", "vmas_ros.envs", "vmas_ros.make_env",
                                                 "vmas_ros.scenarios."))]
    assert not engine, engine
    # `import vmas_ros` itself loads the scenario registry (a name table, no scenario and no torch)
    assert [m for m in loaded if m.startswith("vmas_ros.scenarios")] in ([], ["vmas_ros.scenarios"])


def test_help_lists_every_parameter_from_both_entry_points():
    script = Path(sys.executable).parent / "robot_fleet"
    for argv in ([sys.executable, "-m", "vmas_ros.fleet.node", "--help"], [str(script), "--help"]):
        run = subprocess.run(argv, capture_output=True, text=True, timeout=60, cwd=ROOT)
        assert run.returncode == 0, run.stderr
        assert run.stdout.startswith("usage: robot_fleet")
        listed = set(re.findall(r"^  ([a-z_]+)\s", run.stdout, re.M))
        assert listed == set(FLEET_PARAMS.names())
    assert '"robot_fleet = vmas_ros.fleet.startup:fleet_main"' in (ROOT / "setup.py").read_text()


# ------------------------------------------------------------------ docs/fleet.md
def documented_table() -> Dict[str, str]:
    """name -> documented default, from the table under docs/fleet.md's '## Parameters'."""
    text = DOC.read_text()
    section = text[text.index("## Parameters"):]
    section = section[:section.index("\n## ", 1)]
    table = {}
    for line in section.splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if len(cells) >= 3 and cells[0].startswith("`"):
            table[cells[0].strip("`")] = cells[1].strip("`")
    return table


def same_default(documented: str, actual) -> bool:
    if documented == "empty":
        return actual == ""
    if isinstance(actual, bool):
        return documented == str(actual).lower()
    if isinstance(actual, (int, float)):  # numbers, or expressions of pi such as "pi - 2*pi/360"
        value = eval(documented, {"__builtins__": {}}, {"pi": math.pi})  # our own docs, arithmetic only
        return math.isclose(value, actual, rel_tol=1e-12)
    return documented == actual


def test_docs_document_every_parameter_with_its_default():
    table = documented_table()
    assert set(table) == set(FLEET_PARAMS.names()), (
        f"docs/fleet.md documents {sorted(set(table) - set(FLEET_PARAMS.names()))} which the table lacks and "
        f"lacks {sorted(set(FLEET_PARAMS.names()) - set(table))}")
    wrong = {name: (table[name], p.default) for name, p in FLEET_PARAMS.params.items()
             if not same_default(table[name], p.default)}
    assert not wrong, f"docs/fleet.md: documented default against the table's: {wrong}"


def doc_commands() -> List[str]:
    """Every robot_fleet command line in docs/fleet.md's bash blocks (continuation lines joined)."""
    commands, block = [], None
    for line in DOC.read_text().splitlines():
        if line.startswith("```"):
            block = [] if block is None and line.strip() == "```bash" else None
            continue
        if block is not None:
            block.append(line)
            joined = "\n".join(block)
            if not line.endswith("\\"):
                block.clear()
                command = joined.replace("\\\n", " ").strip()
                if command.startswith(("robot_fleet ", "python -m vmas_ros.fleet.node ")) and "--ros-args" in command:
                    commands.append(command)
    return commands


def bash_words(command: str) -> List[str]:
    """``command`` split into words by bash itself, as a user pasting it would have it."""
    script = 'words() { for word in "$@"; do printf "%s\\0" "$word"; done; }; words ' + command
    run = subprocess.run(["bash", "-c", script], capture_output=True, timeout=30, check=True)
    return run.stdout.decode().split("\0")[:-1]


def test_every_command_in_the_docs_parses_as_ros_arguments_and_valid_values(tmp_path):
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    commands = doc_commands()
    assert len(commands) >= 3, commands
    for command in commands:
        words = bash_words(command)
        args = words[words.index("--ros-args"):]
        context = rclpy.Context()
        rclpy.init(args=["robot_fleet"] + args, context=context, signal_handler_options=SignalHandlerOptions.NO)
        try:
            node = rclpy.create_node("robot_fleet", context=context)
            given = {name: p.value for name, p in node._parameter_overrides.items()}
            node.destroy_node()
        finally:
            rclpy.shutdown(context=context)
        assert given, command
        if "episodes_file" in given:  # the docs write it first; episode contents are checked in test_episodes.py
            given["episodes_file"] = str(tmp_path / Path(given["episodes_file"]).name)
            Path(given["episodes_file"]).write_text("episodes: [{robots: [[0, 0, 0]]}]\n")
        current = FleetParams(**given)
        for name, value in given.items():
            reason = FLEET_PARAMS.validate(name, value, current)
            assert reason is None, f"{command}: {reason}"
