"""When policy_node acts with ``act_on: scan``: once every robot's new scan is in, or one period after the first.

On its timer (``act_on: timer``) policy_node acts on scans that arrived at
some unrelated moment of the period before: on average half a period old, on
top of the robot's own command latency, so its commands answer a world that
has moved on. With ``act_on: scan`` it acts when its inputs are new instead:

* the scans since the last action form a *set*; the set is complete once
  every scanning robot has a scan newer than the one it was last acted on,
  and policy_node acts at once, from the subscription callback of the scan
  that completed it;
* so that one silent or slow robot does not hold the others back, it acts
  anyway one period (``1 / rate_hz``) after the first new scan of the set,
  with what it has: the inputs are judged as on the timer (a robot whose scan
  is older than ``observation_timeout`` gets nothing, and is named);
* a robot whose last scan is older than ``observation_timeout``, or that has
  sent none, is not scanning: no set waits for it, as it could not be
  commanded anyway;
* without a new scan there is no action, so it never acts more often than
  the scans come.

:class:`ScanSets` is that rule alone (no ROS: the caller passes the times).
:class:`ScanTrigger` runs it on a node: arrivals are reported from the
subscription callbacks and the deadline is one timer, created cancelled, armed
with ``reset()`` at the first new scan of a set and cancelled when the node
acts. Everything runs on the node's executor thread: no threads, no locks.
"""
from __future__ import annotations

import math
from typing import Callable, Dict, Iterable, List, Optional

__all__ = ["ScanSets", "ScanTrigger", "scan_topics"]


def scan_topics(topics: Dict[str, type]) -> List[str]:
    """The topics of ``topics`` (topic -> message class, an adapter's ``topics()``) that carry
    sensor_msgs/LaserScan, sorted: the arrivals ``act_on: scan`` acts on."""
    from sensor_msgs.msg import LaserScan

    return sorted(topic for topic, msg_type in topics.items() if msg_type is LaserScan)


class ScanSets:
    """Which scans are new since the last action, and whether the set of them is complete.

    ``topics``: the scan topics that trigger actions (one per robot).
    """

    def __init__(self, topics: Iterable[str]) -> None:
        self.topics: List[str] = list(topics)
        if not self.topics:
            raise ValueError("ScanSets needs at least one scan topic")
        self.received: Dict[str, int] = dict.fromkeys(self.topics, 0)  # scans received so far
        self.used: Dict[str, int] = dict.fromkeys(self.topics, 0)  # ... of which the last action saw
        self.arrival: Dict[str, float] = dict.fromkeys(self.topics, -math.inf)
        #: monotonic time of the first new scan since the last action; None: nothing new
        self.opened: Optional[float] = None

    def arrive(self, topic: str, now: float) -> bool:
        """A scan arrived on ``topic`` at ``now``; True when it is the first new scan of a set."""
        self.received[topic] += 1
        self.arrival[topic] = now
        first = self.opened is None
        if first:
            self.opened = now
        return first

    def new(self) -> List[str]:
        """The topics with a scan newer than the one the last action saw."""
        return [t for t in self.topics if self.received[t] > self.used[t]]

    def pending(self) -> bool:
        """Whether any scan arrived since the last action."""
        return self.opened is not None

    def waiting_for(self, now: float, timeout: float) -> List[str]:
        """The scanning topics (a scan within ``timeout`` of ``now``) that have no new scan yet."""
        return [t for t in self.topics
                if self.received[t] == self.used[t] and now - self.arrival[t] <= timeout]

    def complete(self, now: float, timeout: float) -> bool:
        """Whether something is new and no scanning robot is still to send its new scan."""
        return self.pending() and not self.waiting_for(now, timeout)

    def acted(self) -> None:
        """The node acted on everything received so far: a new set starts."""
        self.used = dict(self.received)
        self.opened = None


class ScanTrigger:
    """Calls ``act()`` on node ``node`` by the rule of :class:`ScanSets`.

    ``period()`` and ``timeout()`` give the current ``1 / rate_hz`` and
    ``observation_timeout`` (both may change at runtime); ``clock()`` is the
    monotonic clock arrivals are timed with. Call :meth:`on_scan` from each
    trigger topic's subscription callback, and :meth:`set_period` when
    ``rate_hz`` changes.
    """

    def __init__(self, node, topics: Iterable[str], act: Callable[[], None], period: Callable[[], float],
                 timeout: Callable[[], float], clock: Callable[[], float]) -> None:
        self.node, self.sets = node, ScanSets(topics)
        self._act, self._period, self._timeout, self._clock = act, period, timeout, clock
        self.actions = 0
        #: clock time of the last action (-inf: none yet)
        self.last_action = -math.inf
        self._deadline = self._new_deadline()

    def _new_deadline(self):
        return self.node.create_timer(self._period(), self._on_deadline, autostart=False)

    def on_scan(self, topic: str) -> None:
        """A scan arrived on trigger topic ``topic`` (its message is already the node's latest)."""
        now = self._clock()
        first = self.sets.arrive(topic, now)
        if self.sets.complete(now, self._timeout()):
            self._fire(now)
        elif first:
            self._deadline.reset()  # counts one period from now

    def _on_deadline(self) -> None:
        self._deadline.cancel()
        if self.sets.pending():
            self._fire(self._clock())

    def _fire(self, now: float) -> None:
        self._deadline.cancel()
        self.sets.acted()
        self.actions += 1
        self.last_action = now
        self._act()

    def set_period(self) -> None:
        """``rate_hz`` changed: the deadline timer takes the new period (an open set's counts from now)."""
        self._deadline.cancel()
        self.node.destroy_timer(self._deadline)
        self._deadline = self._new_deadline()
        if self.sets.pending():
            self._deadline.reset()

    def describe(self) -> str:
        """For the node's start-up line: when it acts."""
        return (f"on every complete set of new scans on {self.sets.topics} (at the latest {self._period():g} s "
                f"after the first of a set)")
