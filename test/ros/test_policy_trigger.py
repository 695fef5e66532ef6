"""``act_on: scan``'s rule alone (no ROS): when a set of new scans is complete, and whom it waits for.

The node-level behaviour (commands following real scans across processes)
is in test_policy_node_scan.py.
"""
from __future__ import annotations

import pytest

from vmas_ros.ros.policy_trigger import ScanSets

TIMEOUT = 0.5
A, B, C = "agent_0/scan", "agent_1/scan", "agent_2/scan"


def test_a_set_is_complete_once_every_robot_has_a_new_scan():
    sets = ScanSets([A, B, C])
    for topic in (A, B, C):  # first scans: each robot's first scan completes what is known so far
        sets.arrive(topic, 0.0)
    assert sets.complete(0.0, TIMEOUT)
    sets.acted()
    assert not sets.pending() and not sets.complete(0.01, TIMEOUT)
    assert sets.arrive(A, 0.1) is True  # the first new scan opens a set ...
    assert sets.arrive(A, 0.12) is False  # ... a second one of the same robot does not complete it
    assert not sets.complete(0.12, TIMEOUT) and sets.waiting_for(0.12, TIMEOUT) == [B, C]
    sets.arrive(B, 0.13)
    assert not sets.complete(0.13, TIMEOUT)
    sets.arrive(C, 0.14)
    assert sets.complete(0.14, TIMEOUT) and sets.new() == [A, B, C] and sets.opened == 0.1


def test_nothing_new_is_never_complete():
    sets = ScanSets([A])
    assert not sets.complete(0.0, TIMEOUT)
    sets.arrive(A, 0.0)
    assert sets.complete(0.0, TIMEOUT)
    sets.acted()
    assert not sets.complete(0.05, TIMEOUT), "acted twice on one scan"


def test_a_robot_that_stopped_scanning_or_never_did_is_not_waited_for():
    sets = ScanSets([A, B, C])  # C never scans
    sets.arrive(A, 0.0)
    assert sets.complete(0.0, TIMEOUT), "B and C have sent nothing yet: no reason to wait for them"
    sets.acted()
    sets.arrive(A, 0.05)
    sets.arrive(B, 0.05)
    assert sets.complete(0.05, TIMEOUT)
    sets.acted()
    sets.arrive(A, 0.1)  # B goes silent after its scan at 0.0
    assert sets.waiting_for(0.1, TIMEOUT) == [B] and not sets.complete(0.1, TIMEOUT)
    sets.acted()  # the node acted on the deadline
    sets.arrive(A, 0.6)
    assert sets.waiting_for(0.6, TIMEOUT) == [], "B's last scan is older than the timeout: nobody to wait for"
    assert sets.complete(0.6, TIMEOUT)


def test_no_topics_is_a_mistake():
    with pytest.raises(ValueError, match="at least one scan topic"):
        ScanSets([])
