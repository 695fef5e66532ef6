"""Why policy_node cannot command an agent: each agent's input topics, and what is wrong with them.

A robot must never be driven from data that is missing, old or broken. For
every agent this module says, in words that name the robot and the topic,
what stops it: no message yet on one of its topics (and how many publishers
that topic has, so a wrong remap shows), a message older than
``observation_timeout``, odometry with a NaN pose, or a problem the adapter
found (a LaserScan it cannot resample). Topics with an agent's name as one of
their path tokens (``agent_1/odom``) are that agent's; the rest (a landmarks
PoseArray) are shared by all.
"""
from __future__ import annotations

import math
from typing import Callable, Dict, Iterable, List, Mapping, Optional, Sequence

import numpy as np

from vmas_ros.adapters.pieces import read_odometry


def yaw_of(msg) -> float:
    """Heading of a nav_msgs/Odometry's pose about +z (NaN when ``read_odometry`` refuses the message)."""
    state, _ = read_odometry(msg)
    return math.nan if state is None else float(state[2])


class AgentInputs:
    """The input topics of each agent and the reasons it gets no command.

    ``topics``: every topic policy_node reads (adapter and odometry);
    ``odom_topics``: one per agent when the command needs the heading, else None.
    """

    def __init__(self, agents: Sequence[str], topics: Iterable[str], odom_topics: Optional[List[str]],
                 timeout: Callable[[], float]) -> None:
        self.agents = list(agents)
        topics = sorted(set(topics) | set(odom_topics or []))
        names = set(self.agents)
        self.own: Dict[str, List[str]] = {a: [t for t in topics if a in t.split("/")] for a in self.agents}
        self.shared = [t for t in topics if not names.intersection(t.split("/"))]
        self.odom_topics = odom_topics
        self.timeout = timeout

    def headings(self, fresh: Mapping[str, object]) -> np.ndarray:
        """Each agent's heading ``[n]`` from its fresh odometry; NaN where there is none or it is broken."""
        if self.odom_topics is None:
            return np.full(len(self.agents), np.nan)
        return np.array([yaw_of(fresh[t]) if t in fresh else math.nan for t in self.odom_topics])

    def _absent(self, topic: str, seen: Mapping[str, object], publishers: Callable[[str], int]) -> str:
        if topic in seen:
            return f"{topic} is older than observation_timeout ({self.timeout():g} s)"
        count = publishers(topic)
        return f"nothing received on {topic} yet ({count} publisher{'' if count == 1 else 's'})"

    def reasons(self, fresh: Mapping[str, object], seen: Mapping[str, object], usable: np.ndarray,
                yaw: np.ndarray, problems: Mapping[str, str], publishers: Callable[[str], int]) -> Dict[int, str]:
        """Agent index -> why it gets no command, for every agent that gets none.

        ``fresh``: messages young enough to act on; ``seen``: every topic
        received at least once; ``usable`` ``[n]``: the adapter built a finite
        observation; ``yaw`` ``[n]``: the heading, where one is needed;
        ``problems``: the adapter's own reasons by agent name;
        ``publishers(topic)``: how many publishers a topic has.
        """
        found: Dict[int, str] = {}
        for i, agent in enumerate(self.agents):
            if self.odom_topics is not None and not math.isfinite(yaw[i]):
                topic = self.odom_topics[i]
                found[i] = (f"odometry on {topic}: {read_odometry(fresh[topic])[1]}" if topic in fresh
                            else self._absent(topic, seen, publishers))
            elif not usable[i]:
                # what is missing or old is said best here (the adapter sees fresh messages only); what is
                # wrong with messages that did arrive, the adapter says
                missing = [t for t in self.own[agent] + self.shared if t not in fresh]
                found[i] = ("; ".join(self._absent(t, seen, publishers) for t in missing) if missing
                            else problems.get(agent, "the adapter built no finite observation from the messages "
                                                     "received"))
        return found
