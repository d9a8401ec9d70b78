"""Exercise 08.4's heartbeat checker: it accepts the reference, and every criterion fails on a wrong pair."""

from __future__ import annotations

import pytest

from course_helpers.checks.ch08_qos import check_heartbeat
from course_helpers.solutions import ch08_qos as reference

from .test_ch08a_exercises import (
    CREATED,
    AlarmistMonitor,
    AutomaticHeartbeat,
    BoolHeartbeat,
    DeafHeartbeat,
    DeafMonitor,
    ImpatientMonitor,
    LostOnlyMonitor,
    MisspeltMonitor,
    MuteMonitor,
    NamedHeartbeat,
    NamedMonitor,
    NeverBeatingHeartbeat,
    OneWayHeartbeat,
    SeldomHeartbeat,
    StubbornHeartbeat,
)


def _failed(report) -> set[str]:
    return {c.name for c in report.criteria if not c.passed}


def _covered(table) -> set[str]:
    return set().union(*(param.values[1] for param in table))


# each wrong solution is a (heartbeat, monitor) pair: the checker judges the two nodes one after the other
HEARTBEAT_WRONG = [
    pytest.param((NamedHeartbeat, NamedMonitor), {CREATED}, id="constructor-argument"),
    pytest.param((BoolHeartbeat, MisspeltMonitor),
                 {"heartbeat: it has a publisher on /heartbeat (std_msgs/msg/String)",
                  "monitor: it subscribes to /heartbeat (std_msgs/msg/String)"}, id="type-and-topic"),
    pytest.param((AutomaticHeartbeat, ImpatientMonitor),
                 {"heartbeat: MANUAL_BY_TOPIC with a lease of at most 1 s",
                  "monitor: compatible with a MANUAL_BY_TOPIC heartbeat, lease 0.5 s"}, id="qos"),
    pytest.param((DeafHeartbeat, MuteMonitor),
                 {"heartbeat: it subscribes to /heartbeat/enable (std_msgs/msg/Bool)",
                  "monitor: it publishes on /heartbeat/status (std_msgs/msg/String)"}, id="missing-endpoint"),
    pytest.param((NeverBeatingHeartbeat, AlarmistMonitor),
                 {"heartbeat: a monitor sees it alive",
                  "monitor: says nothing is lost while the heartbeat asserts every 0.1 s"},
                 id="silent-alarmist"),
    pytest.param((SeldomHeartbeat, LostOnlyMonitor),
                 {"heartbeat: alive through 6 leases, with at most 1 of them lost",
                  "monitor: publishes 'alive' when the heartbeat is back"}, id="seldom-lost-only"),
    pytest.param((StubbornHeartbeat, DeafMonitor),
                 {"heartbeat: lost within 2 s of a False on /heartbeat/enable",
                  "monitor: publishes 'lost' within 2 s after the heartbeat stopped",
                  "monitor: publishes 'alive' when the heartbeat is back"}, id="stubborn-deaf"),
    pytest.param((OneWayHeartbeat, reference.HeartbeatMonitor), {"heartbeat: alive again after a True"},
                 id="one-way"),
]


def test_heartbeat_checker_accepts_the_reference_and_every_criterion_has_a_wrong_solution(rt):
    report = check_heartbeat(*reference.heartbeat_nodes(), rt)
    assert report.passed, report.summary()
    assert {c.name for c in report.criteria} <= _covered(HEARTBEAT_WRONG)


@pytest.mark.parametrize("wrong, failing", HEARTBEAT_WRONG)
def test_heartbeat_checker_fails_each_criterion_on_a_wrong_solution(rt, wrong, failing):
    report = check_heartbeat(*wrong, rt)
    assert not report.passed
    assert failing <= _failed(report), report.summary()
