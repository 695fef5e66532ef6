"""Every mapping-valued ``-p`` in README.md and docs/*.md works when pasted into a shell.

A ROS 2 parameter that holds a mapping (``scenario_kwargs``,
``adapter_kwargs``) must reach rcl as a YAML string: the shell strips one
layer of quotes, and rcl refuses a bare ``{...}`` ("Couldn't parse parameter
override rule ... Unknown YAML event"). So for every ``-p`` word in the shell
code blocks and inline code of the pages, this test

1. expands the word as bash does (quote removal, ``$VAR`` with the sample
   values in ``SAMPLES``, word splitting), in a child ``bash`` that only
   prints the words (command substitutions are refused, never run);
2. keeps the words whose value is a ``{...}`` mapping, bare or YAML-quoted;
3. gives each to rcl as ``--ros-args -p WORD`` in a fresh rclpy context and
   reads back the parameter override of a node;
4. checks that value with the parameter table of the node the command
   starts (``NODES``; for a bare ``-p`` in prose, the node that declares it).
"""
from __future__ import annotations

import re
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, List, Optional, Tuple

import pytest

pytestmark = pytest.mark.ros  # rcl parses the rules

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))

#: sample values of the shell variables the pages' -p words use (what the surrounding commands set)
SAMPLES = {"KW": '{"n_agents": 3, "collisions": true}'}
#: code blocks in these languages (or none) hold shell commands
SHELL_LANGUAGES = {"", "bash", "sh", "shell", "console", "zsh"}
_FENCE = re.compile(r"^\s*(```|~~~)\s*([\w+-]*)")
_INLINE = re.compile(r"`([^`]+)`")
_VARIABLE = re.compile(r"\$\{?([A-Za-z_]\w*)")
_OPERATORS = set(";|&<>()")
#: node -> (what in a command starts it, the module and name of its parameter table)
NODES = {
    "sim_node": (("sim_node", "vmas-ros sim"), "vmas_ros.ros.params", "SIM_PARAMS"),
    "policy_node": (("policy_node",), "vmas_ros.ros.params", "POLICY_PARAMS"),
    "robot_fleet": (("robot_fleet", "vmas_ros.fleet"), "vmas_ros.fleet.params", "FLEET_PARAMS"),
}


@dataclass
class Command:
    """One shell command of a page: where it is and its text (continuation lines joined)."""

    page: str
    line: int
    text: str


def commands(page: Path) -> Iterator[Command]:
    """The shell commands of ``page``: each line of a shell code block (``\\`` continuations joined), and
    each inline code span outside the blocks that passes a ``-p``."""
    lines = page.read_text(encoding="utf-8").splitlines()
    name = str(page.relative_to(ROOT))
    prose: List[Tuple[int, str]] = []
    language: Optional[str] = None  # inside a block: its language
    pending, start = "", 0
    for number, line in enumerate(lines, 1):
        fence = _FENCE.match(line)
        if fence:
            language = fence.group(2).lower() if language is None else None
            continue
        if language is None:
            prose.append((number, line))
        elif language in SHELL_LANGUAGES:
            if not pending:
                start = number
            if line.rstrip().endswith("\\"):
                pending += line.rstrip()[:-1] + " "
                continue
            yield Command(name, start, pending + line)
            pending = ""
    text = "\n".join(line for _, line in prose)
    for match in _INLINE.finditer(text):
        if re.search(r"(^|\s)-p\s", match.group(1)):
            number = prose[text.count("\n", 0, match.start())][0]
            yield Command(name, number, match.group(1).replace("\n", " "))


def raw_words(text: str) -> List[str]:
    """``text`` split into shell words as typed (quotes kept), up to a comment; an unquoted operator
    (``;``, ``|``, ``&``, ...) is a word of its own."""
    words: List[str] = []
    word, quote, in_word, i = "", None, False, 0
    while i < len(text):
        c = text[i]
        if quote == "'":
            word += c
            quote = None if c == "'" else quote
        elif quote == '"':
            word += c
            if c == "\\" and i + 1 < len(text):
                word += text[i + 1]
                i += 1
            elif c == '"':
                quote = None
        elif c in "'\"":
            word, quote, in_word = word + c, c, True
        elif c == "\\" and i + 1 < len(text):
            word, in_word = word + c + text[i + 1], True
            i += 1
        elif c.isspace() or c in _OPERATORS:
            if in_word:
                words.append(word)
                word, in_word = "", False
            if c in _OPERATORS:
                words.append(c)
        elif c == "#" and not in_word:
            break
        else:
            word, in_word = word + c, True
        i += 1
    if in_word:
        words.append(word)
    return words


def expand(word: str, directory: Path) -> List[str]:
    """The words bash makes of ``word`` typed on a command line, with ``SAMPLES`` for its variables."""
    if "$(" in word or "`" in word:
        raise ValueError(f"{word!r} runs a command: give an example value instead")
    unknown = sorted(set(_VARIABLE.findall(word)) - set(SAMPLES))
    if unknown:
        raise ValueError(f"{word!r} uses ${', $'.join(unknown)}: add a sample value to SAMPLES")
    result = subprocess.run(["bash", "--norc", "--noprofile", "-c", f"printf '%s\\0' {word}"], cwd=directory,
                            env={"PATH": "/usr/bin:/bin", **SAMPLES}, capture_output=True, text=True, timeout=10)
    if result.returncode != 0:
        raise ValueError(f"bash cannot read {word!r}: {result.stderr.strip()}")
    return result.stdout.split("\0")[:-1]


def mapping_valued(word: str) -> bool:
    """Whether the value of ``name:=value`` is meant as a ``{...}`` mapping, bare or in one layer of YAML
    quotes (also one the shell cut short at a space: ``{n_agents:``)."""
    value = word.split(":=", 1)[1].strip()
    return value.lstrip("'\"").startswith("{")


def rcl_value(word: str, node_name: str):
    """The value rcl gives node ``node_name`` for ``--ros-args -p word``; raises rcl's error if it refuses."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    context = rclpy.Context()
    rclpy.init(context=context, args=["docs", "--ros-args", "-p", word], signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = rclpy.create_node(node_name, context=context, start_parameter_services=False, enable_rosout=False)
        try:
            return node._parameter_overrides[word.split(":=", 1)[0]].value
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def _node_of(text: str, name: str):
    """(node name, parameter table) of the node a command starts, or, for a bare ``-p``, of the one node
    that declares ``name``; raises ValueError when that cannot be told."""
    import importlib

    tables = {node: getattr(importlib.import_module(module), table) for node, (_, module, table) in NODES.items()}
    started = [node for node, (words, _, _) in NODES.items() if any(word in text for word in words)]
    if not started:
        started = [node for node, table in tables.items() if name in table.params]
    if len(started) != 1:
        raise ValueError(f"cannot tell which node it is for (candidates: {started or 'none'})")
    return started[0], tables[started[0]]


def check(command: Command, directory: Path) -> Tuple[int, List[str]]:
    """(mapping-valued -p words found, what is wrong with them) in one command."""
    words = raw_words(command.text)
    found, problems = 0, []
    for flag, word in zip(words, words[1:]):
        if flag != "-p" or ":=" not in word:
            continue
        where = f"{command.page}:{command.line}: -p {word}"
        try:
            expanded = expand(word, directory)
        except ValueError as error:
            problems.append(f"{where}: {error}")
            continue
        if not expanded or ":=" not in expanded[0] or not mapping_valued(expanded[0]):
            continue
        found += 1
        if len(expanded) > 1:
            problems.append(f"{where}: the shell splits it into {len(expanded)} words {expanded}")
            continue
        name = expanded[0].split(":=", 1)[0]
        try:
            node, table = _node_of(command.text, name)
        except ValueError as error:
            problems.append(f"{where}: {error}")
            continue
        try:
            value = rcl_value(expanded[0], node)
        except Exception as error:  # rclpy's RCLError: rcl refused the rule
            problems.append(f"{where}: rcl refuses {expanded[0]!r}: {str(error).split(', at ')[0]}")
            continue
        if reason := table.validate(name, value):
            problems.append(f"{where}: {node} refuses {value!r}: {reason}")
    return found, problems


def test_mapping_parameters_in_the_docs_work_when_pasted(tmp_path):
    found, problems, pages = 0, [], set()
    for page in PAGES:
        for command in commands(page):
            count, wrong = check(command, tmp_path)
            found += count
            problems += wrong
            if count:
                pages.add(command.page)
    assert not problems, "\n".join(problems)
    # the pages that show mapping parameters today: the extractor must keep finding them
    assert {"docs/vmas_compat.md", "docs/node.md", "docs/policy_node.md"} <= pages, pages
    assert found >= 4, found


@pytest.mark.parametrize("text, good", [
    ('sim_node --ros-args -p scenario:=navigation -p scenario_kwargs:="$KW" -p control:=zero', False),
    ("sim_node --ros-args -p scenario_kwargs:={n_agents: 4}", False),  # split by the shell
    ("sim_node --ros-args -p 'scenario_kwargs:={\"n_agents\": 4}'", False),  # a bare mapping reaches rcl
    ("sim_node --ros-args -p \"scenario_kwargs:='$KW'\" -p control:=zero", True),
    ("sim_node --ros-args -p 'scenario_kwargs:=\"{n_agents: 4}\"'", True),
    ("policy_node --ros-args -p 'adapter_kwargs:=\"{landmarks_topic: /goals}\"'", True),
    ("sim_node --ros-args -p \"scenario_kwargs:='{n_agents: [}'\"", False),  # rcl takes it, the node does not
])
def test_the_check_tells_working_forms_from_broken_ones(text, good, tmp_path):
    found, problems = check(Command("example", 1, text), tmp_path)
    assert found == 1
    assert (not problems) == good, problems
