"""The adapter hook: what ``policy_node`` asks of an observation adapter, the default one, and loading by name.

A trained policy expects the exact vector the scenario's ``observation()``
built in training. In simulation, sim_node publishes that vector on
``<agent>/observation`` (:class:`TopicObservations`, the default). A real
robot has no such topic: it has odometry, scans and goal poses. An adapter
rebuilds the training observation from those standard messages, so the same
exported policy runs on hardware.

The hook (select one with ``-p adapter:=navigation`` or ``package.module:Class``)::

    class MyAdapter(ObservationAdapter):
        def __init__(self, agents, observation_size, **adapter_kwargs): ...
        def topics(self) -> Dict[str, type]:       # topic -> message class to subscribe
            return {f"{a}/odom": Odometry for a in self.agents}
        def build(self, latest) -> np.ndarray:     # [n_agents, observation_size]
            self.problems = {}
            ...

``latest`` maps each topic to its newest message that is not older than
``observation_timeout``; stale and missing topics are absent. A row the
adapter cannot build is NaN, and ``problems`` says why: policy_node does not
act for that agent and warns with the reason. Relative topic names follow
the node's namespace (``--ros-args -r __ns:=/robot1``).

Nothing here imports rclpy or torch: message classes are imported inside
``topics()``, and messages are read by their fields only, so plain objects
with the same fields work too.
"""
from __future__ import annotations

import abc
import importlib
from typing import Any, Dict, Mapping, Optional, Sequence, Set

import numpy as np

__all__ = ["ObservationAdapter", "TopicObservations", "agent_topic", "load_adapter"]


def agent_topic(template: str, agent: str, agents: Sequence[str], kwarg: str) -> str:
    """``template`` with ``{agent}`` replaced by ``agent``; ValueError unless it is a non-empty string that
    names ``{agent}`` (several agents cannot share one topic)."""
    if not isinstance(template, str) or not template:
        raise ValueError(f"{kwarg} must be a non-empty topic name, got {template!r}")
    if "{agent}" not in template and len(agents) > 1:
        raise ValueError(f"{kwarg} must contain '{{agent}}' (one topic per agent), got {template!r}")
    return template.replace("{agent}", agent)


class ObservationAdapter(abc.ABC):
    """Base of observation adapters: the agents' names and the policy's observation size.

    The contract with policy_node:

    * ``topics()``: topic name -> message class of every topic ``build`` reads;
      ``standing_topics()``: those whose last message never goes stale (goals).
    * ``build(latest)``: the observations ``[n_agents, observation_size]``
      (float32), one row per agent in ``agents`` order; a row that cannot be
      built is all NaN.
    * ``problems``: after each ``build``, agent name -> why its row is NaN
      (one line naming the topic, e.g. ``"agent_1/odom: NaN pose"`` or
      ``"agent_0/scan: scan covers [-1.57, 1.57] rad, the training lidar needs
      rays all round the circle"``); agents whose row is usable are absent.
      policy_node logs it with the agents' names.

    Constructor errors (a size that does not fit the task, a bad kwarg) are
    ValueErrors naming the value and what was expected: policy_node refuses
    to start with that reason.
    """

    def __init__(self, agents: Sequence[str], observation_size: int, **kwargs: Any) -> None:
        if kwargs:
            raise ValueError(f"{type(self).__name__} takes no adapter_kwargs, got {sorted(kwargs)}")
        self.agents = list(agents)
        self.observation_size = int(observation_size)
        #: agent -> why its row of the last build is NaN (absent: the row is usable)
        self.problems: Dict[str, str] = {}

    @abc.abstractmethod
    def topics(self) -> Dict[str, type]:
        """Topic name -> message class of every topic ``build`` reads."""

    def standing_topics(self) -> Set[str]:
        """Topics whose last message stands until a new one replaces it (goals, landmarks), of ``topics()``.

        A sensor stream (odometry, scans) is too old to act on after
        ``observation_timeout``; a goal is not: a planner may send it once, or
        at a slow rate. policy_node passes a standing topic's last message to
        ``build`` whatever its age. None by default.
        """
        return set()

    @abc.abstractmethod
    def build(self, latest: Mapping[str, Any]) -> np.ndarray:
        """The observations [n_agents, observation_size]; NaN rows (and a ``problems`` entry) where inputs
        are missing or unusable."""

    @classmethod
    def kwargs_from_training(cls, scenario_kwargs: Mapping[str, Any]) -> Dict[str, Any]:
        """Adapter kwargs the policy's training kwargs decide (its JSON's ``scenario_kwargs``); none here.

        A shipped adapter overrides this, so that a policy trained with, say,
        diff-drive agents is never read with a holonomic layout that happens to
        have the same size; ``adapter_kwargs`` given by the user still win.
        """
        return {}

    def empty(self) -> np.ndarray:
        """All-NaN observations [n_agents, observation_size], float32."""
        return np.full((len(self.agents), self.observation_size), np.nan, dtype=np.float32)

    def note(self, agent: str, problem: str) -> None:
        """Record why ``agent``'s row is NaN (several reasons are joined with '; ')."""
        self.problems[agent] = f"{self.problems[agent]}; {problem}" if agent in self.problems else problem


class TopicObservations(ObservationAdapter):
    """The default: each agent's ``<agent>/observation`` (sim_node publishes it), used as is."""

    def topics(self) -> Dict[str, type]:
        from std_msgs.msg import Float32MultiArray

        return {f"{agent}/observation": Float32MultiArray for agent in self.agents}

    def build(self, latest: Mapping[str, Any]) -> np.ndarray:
        obs, self.problems = self.empty(), {}
        for i, agent in enumerate(self.agents):
            topic = f"{agent}/observation"
            msg = latest.get(topic)
            if msg is None:
                self.note(agent, f"{topic}: no message")
            elif len(msg.data) != self.observation_size:
                self.note(agent, f"{topic}: {len(msg.data)} values, expected {self.observation_size}")
            else:
                obs[i] = np.asarray(msg.data, dtype=np.float32)
        return obs


#: short adapter name -> ``package.module:Class`` (each is the scenario of the same name)
ADAPTER_NAMES = {
    "diff_drive": "vmas_ros.adapters.tasks:DiffDriveAdapter",
    "goal": "vmas_ros.adapters.tasks:GoalAdapter",
    "navigation": "vmas_ros.adapters.tasks:NavigationAdapter",
    "simple_spread": "vmas_ros.adapters.tasks:SimpleSpreadAdapter",
}


def load_adapter(spec: str, agents: Sequence[str], observation_size: int, kwargs: Dict[str, Any],
                 scenario_kwargs: Optional[Mapping[str, Any]] = None) -> ObservationAdapter:
    """The adapter named by ``spec``, constructed: a short name of ``vmas_ros.adapters.ADAPTER_NAMES``
    (``navigation``, ``simple_spread``, ...), ``package.module:Class``, or empty for ``TopicObservations``.

    ``scenario_kwargs`` (the policy's training kwargs) fill the adapter kwargs
    they decide (:meth:`ObservationAdapter.kwargs_from_training`) that
    ``kwargs`` does not give. Raises ValueError with the reason, so
    policy_node can refuse to start.
    """
    if not spec:
        return TopicObservations(agents, observation_size, **kwargs)
    path = ADAPTER_NAMES.get(spec, spec)
    module_name, _, class_name = path.partition(":")
    if not module_name or not class_name:
        raise ValueError(f"unknown adapter {spec!r}: expected one of {', '.join(sorted(ADAPTER_NAMES))} "
                         f"or 'package.module:Class'")
    try:
        cls = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError) as error:
        raise ValueError(f"cannot import adapter {spec!r}: {error}") from None
    trained = getattr(cls, "kwargs_from_training", None)
    if scenario_kwargs is not None and callable(trained):
        kwargs = {**trained(scenario_kwargs), **kwargs}
    try:
        adapter = cls(agents, observation_size, **kwargs)
    except (TypeError, ValueError) as error:
        raise ValueError(f"adapter {spec!r} refused its arguments: {error}") from None
    if not callable(getattr(adapter, "topics", None)) or not callable(getattr(adapter, "build", None)):
        raise ValueError(f"adapter {spec!r} must have topics() and build(latest) (see vmas_ros.adapters.base)")
    return adapter
