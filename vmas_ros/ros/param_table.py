"""A node's parameters declared once: type, default, range, meaning, when they may change.

Every node (sim_node, policy_node) lists its parameters as :class:`Param`
entries in a :class:`ParamTable`. Everything else is generated from that one
table, so it cannot drift:

* the typed values object the node reads (:meth:`ParamTable.values_class`);
* validation, the same at start-up and for runtime changes
  (:meth:`ParamTable.validate`): a bad value is refused with a reason that
  names it and says what was expected;
* the ROS ``ParameterDescriptor`` of each parameter, with its description,
  range and read-only flag, for ``ros2 param describe`` and ``vmas-ros param
  describe`` (:meth:`ParamTable.descriptor`);
* the ``--help`` text of ``vmas-ros sim`` and ``sim_node --help``
  (:meth:`ParamTable.help`).
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, make_dataclass
from dataclasses import field as dataclass_field
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple

__all__ = ["Param", "ParamTable"]

_KINDS = {bool: "bool", int: "int", float: "float", str: "str"}


@dataclass(frozen=True)
class Param:
    """One parameter.

    ``minimum``/``maximum`` bound a number (``strict``: ``> minimum``);
    ``zero_is_off`` also allows 0 below ``minimum``, meaning "off" (a rate of 0
    is unpaced); ``note`` follows the range in messages (``(0: off)``);
    ``choices`` lists a string's allowed values; ``check(value,
    current)`` adds a rule of its own (``current``: the node's values, None at
    start-up before all are read) and returns why a value is refused, or None.
    """

    name: str
    default: Any
    description: str
    runtime: bool = False
    minimum: Optional[float] = None
    maximum: Optional[float] = None
    strict: bool = False
    zero_is_off: bool = False
    choices: Tuple[str, ...] = ()
    note: str = ""
    check: Optional[Callable[[Any, Any], Optional[str]]] = None

    @property
    def kind(self) -> str:
        """``bool``, ``int``, ``float`` or ``str``: the type of the default."""
        return _KINDS[type(self.default)]

    def bounds(self) -> str:
        """The allowed values in words, e.g. ``in [1, 4096]``, ``0 (off) or in [0.001, 1e+06]``, ``> 0``."""
        if self.choices:
            return "one of " + ", ".join(self.choices)
        if self.minimum is None and self.maximum is None:
            return self.note
        if self.maximum is None:
            text = f"{'>' if self.strict else '>='} {_number(self.minimum)}"
        else:
            text = f"in [{_number(self.minimum)}, {_number(self.maximum)}]"
        text = f"0 (off) or {text}" if self.zero_is_off else text
        return f"{text} {self.note}" if self.note else text

    def refusal(self, value: Any, current: Any = None) -> Optional[str]:
        """Why ``value`` is not acceptable (None when it is)."""
        kind = self.kind
        if kind == "int" and (isinstance(value, bool) or not isinstance(value, int)):
            return f"{self.name} must be an integer, got {value!r}"
        if kind == "float" and (isinstance(value, bool) or not isinstance(value, (int, float))
                                or not math.isfinite(value)):
            return f"{self.name} must be a finite number, got {value!r}"
        if kind == "bool" and not isinstance(value, bool):
            return f"{self.name} must be true or false, got {value!r}"
        if kind == "str" and not isinstance(value, str) and not self._bool_word(value):
            return f"{self.name} must be a string, got {value!r}"
        if self.choices and value not in self.choices and not self._bool_word(value):
            return f"{self.name} must be one of {', '.join(self.choices)}, got {value!r}"
        if kind in ("int", "float") and not (self.zero_is_off and value == 0) and not self._in_range(value):
            return f"{self.name} must be {self.bounds()}, got {value}"
        return self.check(value, current) if self.check is not None else None

    def _bool_word(self, value) -> bool:
        """A bool given for a choice of words that has it (``compile_physics:=true`` arrives as a bool)."""
        return isinstance(value, bool) and str(value).lower() in self.choices

    def _in_range(self, value) -> bool:
        low_ok = self.minimum is None or (value > self.minimum if self.strict else value >= self.minimum)
        return low_ok and (self.maximum is None or value <= self.maximum)


def _number(value: float) -> str:
    return str(value) if isinstance(value, int) else f"{value:g}"


class ParamTable:
    """The parameters of node ``node``, in the order they are documented."""

    def __init__(self, node: str, params: Sequence[Param], doc: str) -> None:
        self.node, self.doc = node, doc
        self.params: Dict[str, Param] = {p.name: p for p in params}
        if len(self.params) != len(params):
            raise ValueError(f"{node}: parameter names repeat")

    # ------------------------------------------------------------- the table
    def names(self) -> List[str]:
        return list(self.params)

    def runtime(self) -> frozenset:
        """The parameters that may change while the node runs."""
        return frozenset(name for name, p in self.params.items() if p.runtime)

    def values_class(self, class_name: str, base: type = object) -> type:
        """A dataclass with one field per parameter (its default), deriving from ``base``; its
        ``names()`` lists the parameters in the table's order."""
        fields = [(p.name, type(p.default), dataclass_field(default=p.default)) for p in self.params.values()]
        names = self.names
        return make_dataclass(class_name, fields, bases=(base,), namespace={"names": staticmethod(names)})

    # ----------------------------------------------------------- validation
    def validate(self, name: str, value: Any, current: Any = None) -> Optional[str]:
        """Why ``value`` is not acceptable for parameter ``name`` (None when it is)."""
        if name not in self.params:
            return f"unknown parameter {name!r}; known: {', '.join(self.params)}"
        return self.params[name].refusal(value, current)

    def unknown(self, given: Iterable[str]) -> Tuple[List[str], List[str]]:
        """Errors and warnings for parameter overrides the node does not declare.

        A name close to a known one (``num_env``) is a typo: an error, because
        the node would otherwise run silently with the default. Other names only
        get a warning: a shared ``/**`` parameter file may carry values for other
        nodes. A nested key under a known name (``num_envs.a``: a mapping in a
        parameter file) is an error; ``qos_overrides.*`` belongs to rclpy.
        """
        known = self.names()
        errors, warnings = [], []
        for name in sorted(set(given) - set(known)):
            if name.startswith("qos_overrides."):
                continue
            root = name.split(".")[0]
            if root in known:  # rcl flattens {num_envs: {a: 1}} to num_envs.a
                errors.append(f"{root} must be a single value, got a nested key {name!r}")
                continue
            if "." in name:
                continue
            close = difflib.get_close_matches(name, known, n=1, cutoff=0.75)
            if close:
                errors.append(f"unknown parameter {name!r} (did you mean {close[0]!r}?)")
            else:
                warnings.append(f"{self.node} ignores unknown parameter {name!r}; known: {', '.join(known)}")
        return errors, warnings

    # ------------------------------------------------------------ ROS side
    def descriptor(self, name: str):
        """The ``rcl_interfaces/ParameterDescriptor`` of ``name``: description, range, read-only.

        Types stay dynamic so that a parameter file may give ``1`` for a
        double; the node's own validation checks the type. A number's plain
        interval is also given as the descriptor's range (which rclpy enforces
        on every change); one where 0 means "off" is described in words only.
        """
        from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

        p = self.params[name]
        when = "may change at runtime" if p.runtime else "start-only (read-only while the node runs)"
        constraints = "; ".join(part for part in (p.kind, p.bounds(), when) if part)
        descriptor = ParameterDescriptor(name=name, description=p.description, additional_constraints=constraints,
                                         read_only=not p.runtime, dynamic_typing=True)
        if p.minimum is not None and p.maximum is not None and not p.zero_is_off and not p.strict:
            if p.kind == "int":
                descriptor.integer_range = [IntegerRange(from_value=int(p.minimum), to_value=int(p.maximum), step=0)]
            elif p.kind == "float":
                descriptor.floating_point_range = [FloatingPointRange(from_value=float(p.minimum),
                                                                      to_value=float(p.maximum), step=0.0)]
        return descriptor

    def declare(self, node, values_class: type, overrides: Dict[str, Any], cross: Sequence[str] = ()):
        """Declare every parameter on rclpy ``node`` and return its values as ``values_class``.

        Values come from ``overrides`` (given in code), then the command line and
        parameter files, then the defaults. All of them are checked before any is
        declared, so a bad start-up value is refused with every reason at once
        (``ConfigError``, exit code 2) rather than by rclpy's range check on the
        first one. ``cross`` names the parameters checked again against all the
        values (``env_index`` against ``num_envs``). Unknown names are refused
        when they look like typos and logged otherwise.
        """
        from vmas_ros.ros.lifecycle import ConfigError

        given = {name: parameter.value for name, parameter in getattr(node, "_parameter_overrides", {}).items()}
        errors, notes = self.unknown(given)
        for note in notes:
            node.get_logger().warning(note)
        values = {name: overrides.get(name, given.get(name, p.default)) for name, p in self.params.items()}
        errors += [error for name, value in values.items() if (error := self.validate(name, value))]
        if not errors:
            current = values_class(**values)
            errors += [error for name in cross if (error := self.validate(name, values[name], current))]
        if errors:
            raise ConfigError("; ".join(errors))
        for name, value in values.items():
            if self.params[name].kind == "float":
                values[name] = float(value)  # a parameter file's 1 for a double
            node.declare_parameter(name, values[name], self.descriptor(name))
        return values_class(**values)

    def refuse_change(self, parameters, current) -> Optional[str]:
        """Why a runtime change of ``parameters`` (rclpy Parameters) must be refused, or None.

        A start-only parameter is refused (rclpy's read-only check says so
        first), as is any value :meth:`validate` refuses against ``current``.
        """
        for parameter in parameters:
            p = self.params.get(parameter.name)
            if p is None:
                return f"unknown parameter {parameter.name!r}; known: {', '.join(self.params)}"
            if not p.runtime:
                return f"{parameter.name} is start-only: restart the node with the new value"
            if error := self.validate(parameter.name, parameter.value, current):
                return error
        return None

    def log_refusals(self, node, current: Callable[[], Any]) -> None:
        """Log every refused runtime change on ``node``'s logger, whoever refuses it.

        rclpy refuses read-only parameters and values outside a descriptor's
        range before the node's own callback runs, so this runs earlier still
        (a pre-set callback) and names each refusal, as the node's own do.
        """
        def pre_set(parameters):
            for parameter in parameters:
                if reason := self.refuse_change([parameter], current()):
                    node.get_logger().warning(f"refused parameter change: {reason}")
            return parameters

        node.add_pre_set_parameters_callback(pre_set)

    # ----------------------------------------------------------------- help
    def help(self) -> str:
        """Every parameter with its type, default, allowed values, when it may change and what it does."""
        lines = [f"{self.node} parameters (-p name:=value, or a --params-file; full reference: {self.doc}):", ""]
        width = max(len(name) for name in self.params)
        for p in self.params.values():
            default = repr(p.default) if p.kind == "str" else str(p.default).lower() if p.kind == "bool" else p.default
            facts = [p.kind, f"default {default}"]
            if p.bounds():
                facts.append(p.bounds())
            facts.append("runtime" if p.runtime else "start-only")
            lines.append(f"  {p.name:<{width}}  {p.description}")
            lines.append(f"  {'':<{width}}  ({'; '.join(facts)})")
        return "\n".join(lines)
