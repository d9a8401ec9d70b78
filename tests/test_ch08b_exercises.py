"""Chapter 08b's task (a QoS for a burst over a lossy link to a slow subscriber) and the lab panel's record.

The checker runs the real lab experiment: the publisher in a child process, the subscriber in this
process, the samples over UDP on a private network link that drops 10 % of the data datagrams.
"""

from __future__ import annotations

import html

import pytest
from rclpy.qos import (
    Duration,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
    qos_profile_system_default,
)

from course_helpers.chapters.ch08b_lab import ExperimentConfig, link_unavailable_reason, qos_lab
from course_helpers.checks.ch08b_lab import BOUNDED, BURST_SAMPLES, LOSS_TARGET, burst_config, check_burst_qos
from course_helpers.solutions.ch08b_lab import burst_qos

from .criteria_registry import assert_reference_criteria

# measures time (rates, latencies, DDS events): make test's timing stage, few workers beside it
pytestmark = pytest.mark.timing

PROFILE = "the QoS is a profile the lab can run"
RAN = "the experiment ran"
LINK = "the lossy link is available"
needs_link = pytest.mark.skipif(link_unavailable_reason() is not None,
                                reason=f"the lossy link: {link_unavailable_reason()}")


def _failed(report) -> set[str]:
    return {c.name for c in report.criteria if not c.passed}


def _covered(table) -> set[str]:
    return set().union(*(param.values[1] for param in table))


BURST_WRONG = [
    pytest.param(None, {PROFILE}, id="left-none"),  # the notebook's burst_qos = None
    pytest.param(qos_profile_system_default, {PROFILE}, id="system-default"),  # the lab runs named policies
    # KEEP_LAST 10, RELIABLE: the reader's queue overwrites samples that the slow callback has not
    # taken yet (a backlog of about 60). Reliability does not bring them back.
    pytest.param(QoSProfile(depth=10), {LOSS_TARGET}, id="default-depth"),
    # best effort, depth 5: "it is a sensor"; the link's losses are never repaired
    pytest.param(qos_profile_sensor_data, {LOSS_TARGET}, id="sensor-data"),
    # best effort with a queue for the whole burst: the slow subscriber is handled, the link is not
    pytest.param(QoSProfile(depth=BURST_SAMPLES, reliability=ReliabilityPolicy.BEST_EFFORT), {LOSS_TARGET},
                 id="best-effort-deep"),
    # reliable with an unbounded history: loses nothing, and could queue without limit
    pytest.param(QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE),
                 {BOUNDED}, id="keep-all"),
    pytest.param(QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE), {BOUNDED}, id="depth-1000"),
]


@needs_link
def test_burst_checker_accepts_the_reference_and_every_criterion_has_a_wrong_solution(rt):
    report = check_burst_qos(burst_qos())
    print(report)
    assert report.passed, report.summary()
    assert_reference_criteria("check_burst_qos", report)
    assert not rt.children()  # the publisher's process is gone


@needs_link
@pytest.mark.parametrize("wrong, failing", BURST_WRONG)
def test_burst_checker_fails_each_criterion_on_a_wrong_solution(rt, wrong, failing):
    report = check_burst_qos(wrong)
    print(report)
    assert not report.passed
    assert failing <= _failed(report), report.summary()


BUSY_LAB_FAILS = {RAN}  # a run of the lab panel in the same kernel


@needs_link
def test_burst_checker_reports_a_busy_lab(rt):
    # No QoS stops the experiment from running (both ends have it, so they always match); a run of
    # the lab panel in the same kernel does.
    lab = qos_lab()
    try:
        lab.start([ExperimentConfig(rate_hz=10, duration_s=20.0, label="busy")])
        assert rt.poll_until(rt.children, 30)  # its publisher runs
        report = check_burst_qos(burst_qos())
    finally:
        lab.close()
    assert _failed(report) == BUSY_LAB_FAILS
    assert "another QoS lab experiment is running" in report.criteria[-1].detail


@pytest.mark.parametrize("qos, words", [
    (None, "must be a rclpy.qos.QoSProfile"),
    (QoSProfile(depth=10, lifespan=Duration(seconds=1)), "leave lifespan unset"),
    (QoSProfile(depth=5000), "depth must be a whole number from 1 to 1000"),
])
def test_burst_checker_explains_a_profile_it_cannot_run(qos, words):
    report = check_burst_qos(qos)
    assert _failed(report) == {PROFILE}
    assert words in report.criteria[0].detail


def test_burst_config_keeps_the_load_and_takes_the_policies():
    config = burst_config(QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1,
                                     reliability=ReliabilityPolicy.BEST_EFFORT))
    assert isinstance(config, ExperimentConfig)
    assert (config.history, config.depth, config.reliability) == ("keep_all", None, "best_effort")
    assert config.count == BURST_SAMPLES and config.processing_ms == 10.0
    assert (config.transport, config.loss_percent) == ("lossy_link", 10)


def test_lab_record_holds_the_table_of_runs_and_the_final_plot(rt):
    lab = qos_lab()
    updates = []

    class KeptRecord:  # stands in for the notebook's Record outside a kernel: keeps each update
        def update(self, text, html_body=None, figure=None):
            updates.append((text, html_body, figure))

    lab.record = KeptRecord()
    try:
        config = ExperimentConfig(reliability="reliable", depth=10, rate_hz=100, duration_s=0.2,
                                  label="small")
        lab.start([config])
        assert lab.wait(60)
        (result,) = lab.results
        text, body, figure = updates[-1]
        machine = result.machine.describe()  # beside the runs when the machine was busy or shared
        shown = result.machine.busy or result.machine.kernels or result.machine.children
        assert text.splitlines() == [f"1. {result.summary()}", *([machine] if shown else [])]
        assert (html.escape(machine) in body) == bool(shown)
        assert "qos-lab-results" in body and "<td style" in body and "small" in body
        assert figure is not None and len(figure.axes) == 3
        count = len(updates)
        lab.wait()
        assert len(updates) == count  # the same runs are recorded once
    finally:
        lab.close()


COVERED = {"check_burst_qos": _covered(BURST_WRONG) | BUSY_LAB_FAILS}
EXEMPT = {"check_burst_qos": {
    LINK: "fails only where private network namespaces are not allowed (then every test of the checker is "
          "skipped); a test cannot take them away from the machine it runs on",
}}
