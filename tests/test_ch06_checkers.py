"""Chapter 06's overheat-monitor checker: it accepts the reference, and every criterion fails on a wrong one.

Real nodes over real Fast DDS: the checker sets parameters through the monitor's parameter
services and measures what it publishes. Each wrong monitor below is a mistake a student makes;
the table names the criteria it must fail, and the test that runs the reference solution checks
that the table covers every criterion the checker reports. (The launch exercise's checker is
tested the same way in test_ch06_launch.py.)
"""

from __future__ import annotations

import pytest
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64, String

from course_helpers.checks.ch06_parameters import check_overheat_monitor
from course_helpers.solutions.ch06_parameters import OverheatMonitor

from .criteria_registry import assert_reference_criteria, failing


def _failed(report) -> set[str]:
    return {c.name for c in report.criteria if not c.passed}


class Monitor(OverheatMonitor):
    """The reference monitor with its steps spelt out, so that each wrong monitor changes one thing."""

    node_name = "overheat_monitor"
    period_s = None  # None: the timer's period is 1 / rate_hz

    def __init__(self, **kwargs):
        Node.__init__(self, self.node_name, **kwargs)
        self.declare_all()
        self.add_on_set_parameters_callback(self.validate)
        self.add_post_set_parameters_callback(self.apply)
        self.temperature = None
        self.publisher = self.create_publisher(String, self.status_topic(), 10)
        self.subscription = self.create_subscription(Float64, "temperature", self.on_temperature, 10)
        self.timer = self.create_timer(self.period_s or 1.0 / self.get_parameter("rate_hz").value,
                                       self.publish_status)

    def declare_all(self):
        self.declare_parameter("status_topic", "overheat_status", self.descriptor("where statuses go",
                                                                                   read_only=True))
        self.declare_parameter("rate_hz", 5.0, self.descriptor("status rate [Hz]", floating_point_range=[
            FloatingPointRange(from_value=1.0, to_value=20.0, step=0.0)]))
        self.declare_parameter("warning_c", 60.0, self.descriptor("warning threshold [°C]"))
        self.declare_parameter("critical_c", 80.0, self.descriptor("critical threshold [°C]"))

    def descriptor(self, description, **fields):
        return ParameterDescriptor(description=description, **fields)

    def status_topic(self):
        return self.get_parameter("status_topic").value

    def publish_status(self):
        self.publisher.publish(String(data=self.classify(self.temperature)))

    def thresholds(self):
        return self.get_parameter("warning_c").value, self.get_parameter("critical_c").value

    def classify(self, celsius):
        warning_c, critical_c = self.thresholds()
        if celsius is None:
            return "no data"
        return "critical" if celsius >= critical_c else "warning" if celsius >= warning_c else "ok"


class MonitorWithoutKwargs(Monitor):
    """Wrong: the constructor takes no keyword arguments, so the checker's overrides cannot reach it."""

    def __init__(self):
        super().__init__()


class MonitorCalledOverheat(Monitor):
    """Wrong: another node name."""

    node_name = "overheat"


class MonitorWithAnIntegerRate(Monitor):
    """Wrong: rate_hz declared as 5, an integer parameter."""

    def declare_all(self):
        self.declare_parameter("status_topic", "overheat_status", self.descriptor("where", read_only=True))
        self.declare_parameter("rate_hz", 5, self.descriptor("status rate [Hz]"))
        self.declare_parameter("warning_c", 60.0, self.descriptor("warning threshold [°C]"))
        self.declare_parameter("critical_c", 80.0, self.descriptor("critical threshold [°C]"))


class MonitorWithoutStatusTopic(Monitor):
    """Wrong: a fixed topic instead of the status_topic parameter."""

    def declare_all(self):
        self.declare_parameter("rate_hz", 5.0, self.descriptor("status rate [Hz]", floating_point_range=[
            FloatingPointRange(from_value=1.0, to_value=20.0, step=0.0)]))
        self.declare_parameter("warning_c", 60.0, self.descriptor("warning threshold [°C]"))
        self.declare_parameter("critical_c", 80.0, self.descriptor("critical threshold [°C]"))

    def status_topic(self):
        return "overheat_status"


class MonitorWithoutDescriptions(Monitor):
    """Wrong: descriptors with their rules but without descriptions."""

    def descriptor(self, description, **fields):
        return ParameterDescriptor(**fields)


class MonitorIgnoringKwargs(Monitor):
    """Wrong: takes **kwargs and drops them, so the checker's status_topic never arrives."""

    def __init__(self, **kwargs):
        super().__init__()


class MonitorOnTheDefaultTopic(Monitor):
    """Wrong: publishes on the default topic, not on the value of status_topic."""

    def status_topic(self):
        return "overheat_status"


class MonitorSaysOkWithoutData(Monitor):
    """Wrong: reports 'ok' before the first reading."""

    def classify(self, celsius):
        return super().classify(celsius if celsius is not None else 0.0)


class MonitorWithAWritableTopic(Monitor):
    """Wrong: status_topic is not read-only."""

    def descriptor(self, description, **fields):
        fields.pop("read_only", None)
        return ParameterDescriptor(description=description, **fields)


class MonitorWithoutRange(Monitor):
    """Wrong: rate_hz has no range."""

    def descriptor(self, description, **fields):
        fields.pop("floating_point_range", None)
        return ParameterDescriptor(description=description, **fields)


class MonitorWithoutValidation(Monitor):
    """Wrong: accepts every threshold change."""

    def validate(self, parameters):
        return SetParametersResult(successful=True)


class MonitorValidatingBackwards(Monitor):
    """Wrong: the comparison the wrong way round: rejects warning_c below critical_c, accepts the rest."""

    def validate(self, parameters):
        values = dict(zip(("warning_c", "critical_c"), self.thresholds(), strict=True))
        values.update({p.name: p.value for p in parameters if p.name in values})
        if values["warning_c"] < values["critical_c"] and any(p.name in values for p in parameters):
            return SetParametersResult(successful=False, reason="warning_c must be below critical_c")
        return SetParametersResult(successful=True)


class MonitorSaysNormal(Monitor):
    """Wrong: 'normal' instead of 'ok'."""

    def classify(self, celsius):
        status = super().classify(celsius)
        return "normal" if status == "ok" else status


class MonitorWithSwappedLabels(Monitor):
    """Wrong: 'warning' and 'critical' swapped."""

    def classify(self, celsius):
        status = super().classify(celsius)
        return {"warning": "critical", "critical": "warning"}.get(status, status)


class MonitorWithStartupThresholds(Monitor):
    """Wrong: classifies with the thresholds read once, at start-up."""

    def declare_all(self):
        super().declare_all()
        self.startup_thresholds = super().thresholds()

    def thresholds(self):
        return self.startup_thresholds


class MonitorWithAFixedPeriod(Monitor):
    """Wrong: a hard-coded 0.1 s timer period, and no retuning."""

    period_s = 0.1

    def apply(self, parameters):
        pass


class MonitorWithoutParameterServices(Monitor):
    """Wrong: turns the parameter services off, so nobody can retune it from outside (ros2 param set)."""

    def __init__(self, **kwargs):
        super().__init__(start_parameter_services=False, **kwargs)


class MonitorReadingTheWholeMessage(Monitor):
    """Wrong: stores float(msg) instead of msg.data (a TypeError in the subscription's callback)."""

    def on_temperature(self, msg):
        self.temperature = float(msg)


STATUS = "(warning_c 50, critical_c 80) it reports"
OVERHEAT_WRONG = [
    pytest.param(MonitorWithoutParameterServices, {"its parameter services answer"}, id="no-services"),
    pytest.param(MonitorReadingTheWholeMessage, {"callbacks raised no errors"}, id="error-in-a-callback"),
    pytest.param(MonitorWithoutKwargs, {"the node can be created with parameter overrides"}, id="no-kwargs"),
    pytest.param(MonitorCalledOverheat, {"the node is called overheat_monitor"}, id="name"),
    pytest.param(MonitorWithAnIntegerRate,
                 {"it declares rate_hz = 5.0, warning_c = 60.0 and critical_c = 80.0 (floats)"},
                 id="integer"),
    pytest.param(MonitorWithoutStatusTopic, {"it declares status_topic"}, id="no-status-topic"),
    pytest.param(MonitorWithoutDescriptions, {"every parameter is declared with a description"},
                 id="no-descriptions"),
    pytest.param(MonitorIgnoringKwargs,
                 {"status_topic takes the value given at start (a parameter override)"}, id="kwargs-dropped"),
    pytest.param(MonitorOnTheDefaultTopic,
                 {"it publishes its status on status_topic (/overheat_check/status)"}, id="default-topic"),
    pytest.param(MonitorSaysOkWithoutData, {"before any temperature it reports 'no data'"}, id="no-data"),
    pytest.param(MonitorWithAWritableTopic, {"status_topic is read-only (a change is rejected)"},
                 id="writable"),
    pytest.param(MonitorWithoutRange, {"rate_hz = 0.2 is rejected (allowed 1.0 to 20.0)",
                                       "rate_hz = 50 is rejected (allowed 1.0 to 20.0)"}, id="no-range"),
    pytest.param(MonitorWithoutValidation,
                 {"warning_c = 90 is rejected with a reason naming warning_c and critical_c",
                  "critical_c = 50 is rejected with a reason naming warning_c and critical_c"},
                 id="no-validation"),
    pytest.param(MonitorValidatingBackwards,
                 {"warning_c = 50 is accepted", "after critical_c is set to 90, 85 °C becomes 'warning'"},
                 id="validation-backwards"),
    pytest.param(MonitorSaysNormal, {f"at 25 °C {STATUS} 'ok'"}, id="normal"),
    pytest.param(MonitorWithSwappedLabels, {f"at 55 °C {STATUS} 'warning'", f"at 85 °C {STATUS} 'critical'"},
                 id="swapped-labels"),
    pytest.param(MonitorWithStartupThresholds, {"after critical_c is set to 90, 85 °C becomes 'warning'"},
                 id="startup-thresholds"),
    pytest.param(MonitorWithAFixedPeriod, {"it publishes at 5 Hz by default",
                                           "after rate_hz is set to 20, it publishes at 20 Hz"},
                 id="fixed-period"),
]


@pytest.mark.parametrize("monitor", [OverheatMonitor, Monitor], ids=["reference", "reference-spelt-out"])
def test_overheat_checker_accepts_the_reference_and_every_criterion_has_a_wrong_solution(rt, monitor):
    report = check_overheat_monitor(monitor, rt)
    assert report.passed, report.summary()
    assert_reference_criteria("check_overheat_monitor", report)


@pytest.mark.parametrize("wrong, failing", OVERHEAT_WRONG)
def test_overheat_checker_fails_each_criterion_on_a_wrong_solution(rt, wrong, failing):
    report = check_overheat_monitor(wrong, rt)
    assert not report.passed
    assert failing <= _failed(report), report.summary()


def test_validation_callback_rejects_bad_thresholds_with_its_reason(rt):
    node = rt.add(OverheatMonitor)
    result = node.set_parameters([Parameter("warning_c", value=90.0)])[0]
    assert not result.successful
    assert result.reason == "warning_c (90.0) must be below critical_c (80.0)"
    result = node.set_parameters([Parameter("rate_hz", value=0.2)])[0]
    assert not result.successful and "out of range" in result.reason
    assert node.set_parameters([Parameter("warning_c", value=50.0)])[0].successful
    assert node.get_parameter("warning_c").value == 50.0


COVERED = {"check_overheat_monitor": failing(OVERHEAT_WRONG)}
ONLY_WHEN_FAILING = {"check_overheat_monitor": {"the node can be created with parameter overrides",
                                               "it declares status_topic"}}
