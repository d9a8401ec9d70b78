"""Checker of chapter 06 (parameters): the configurable overheat monitor."""

from __future__ import annotations

import threading
import time

from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from std_msgs.msg import Float64, String

from course_helpers.checks import CheckReport
from course_helpers.core.runtime import get_runtime
from course_helpers.core.waiting import poll_until

STATUS_TOPIC = "/overheat_check/status"  # the checker's override of status_topic
DEFAULTS = {"rate_hz": 5.0, "warning_c": 60.0, "critical_c": 80.0}
SETTLE_S = 0.25  # a retuned timer's first period may still be the old one [s]


class OverheatProbe(Node):
    """The checker's side: publishes temperatures, records statuses, sets the monitor's parameters."""

    def __init__(self, rt, name: str = "overheat_checker"):
        super().__init__(name)
        self.rt = rt
        self.lock = threading.Lock()
        self.statuses: list[tuple[float, str]] = []  # (monotonic arrival time [s], status)
        self.status_subscription = self.create_subscription(String, STATUS_TOPIC, self.on_status, 50)
        self.temperature = self.create_publisher(Float64, "/temperature", 10)
        self.monitor_parameters = AsyncParameterClient(self, "/overheat_monitor")

    def on_status(self, msg: String) -> None:
        with self.lock:
            self.statuses.append((time.monotonic(), msg.data))

    def latest(self) -> str | None:
        """The newest status received, or None."""
        with self.lock:
            return self.statuses[-1][1] if self.statuses else None

    def set_remote(self, name: str, value):
        """Set one parameter through the monitor's set_parameters service; returns its SetParametersResult."""
        future = self.monitor_parameters.set_parameters([Parameter(name, value=value)])
        return self.rt.wait_for_future(future, 3.0, f"setting {name}").results[0]

    def status_after(self, celsius: float | None, expected: str, timeout_s: float = 1.5) -> str | None:
        """Publish a temperature (unless None), wait up to ``timeout_s`` for status ``expected``.

        Returns the newest status then (``expected`` if it came).
        """
        if celsius is not None:
            self.temperature.publish(Float64(data=float(celsius)))
        poll_until(lambda: self.latest() == expected, timeout_s)
        return self.latest()

    def status_rate(self, seconds: float = 1.0) -> float:
        """The status rate [Hz] measured over the next ``seconds`` (after letting a retuned timer settle)."""
        time.sleep(SETTLE_S)
        start = time.monotonic()
        time.sleep(seconds)  # the measurement window
        with self.lock:
            stamps = [t for t, _ in self.statuses if t >= start]
        if len(stamps) < 3:
            return len(stamps) / seconds
        return (len(stamps) - 1) / (stamps[-1] - stamps[0])


def check_overheat_monitor(node_class, rt=None) -> CheckReport:
    """Exercise 06: set good and bad parameters on ``node_class`` and watch what it publishes.

    ``node_class`` must pass ``**kwargs`` on to Node (the checker overrides status_topic).
    Returns the CheckReport; ``rt`` defaults to this kernel's runtime.
    """
    rt = rt or get_runtime()
    report = CheckReport("Exercise 06 - configurable overheat monitor")
    overrides = [Parameter("status_topic", value=STATUS_TOPIC)]
    node = report.run("the node can be created with parameter overrides",
                      lambda: rt.add(node_class, parameter_overrides=overrides, console=False),
                      hint="def __init__(self, **kwargs): super().__init__('overheat_monitor', **kwargs)")
    if node is None:
        return report
    probe = rt.add(OverheatProbe, rt, console=False)
    try:
        if _check_declarations(report, node):
            _check_behaviour(report, probe)
    finally:
        rt.remove(probe)
        rt.remove(node)
    return report


def _check_declarations(report: CheckReport, node: Node) -> bool:
    named = node.get_name() == "overheat_monitor"
    if not report.add("the node is called overheat_monitor", named,
                      "" if named else f"it is called {node.get_name()!r}",
                      "super().__init__('overheat_monitor', **kwargs)"):
        return False
    wrong = []
    for name, default in DEFAULTS.items():
        if not node.has_parameter(name):
            wrong.append(f"{name} is not declared")
        elif (node.get_parameter(name).type_ != Parameter.Type.DOUBLE
              or node.get_parameter(name).value != default):
            wrong.append(f"{name} = {node.get_parameter(name).value!r}")
    report.add("it declares rate_hz = 5.0, warning_c = 60.0 and critical_c = 80.0 (floats)", not wrong,
               "; ".join(wrong), "self.declare_parameter('rate_hz', 5.0, descriptor); write 5.0, not 5, "
               "so the parameter is a double.")
    if not node.has_parameter("status_topic"):
        report.add("it declares status_topic", False, "", "self.declare_parameter('status_topic', "
                   "'overheat_status', ParameterDescriptor(read_only=True))")
        return False
    report.add("status_topic takes the value given at start (a parameter override)",
               node.get_parameter("status_topic").value == STATUS_TOPIC, "",
               "Pass **kwargs on to super().__init__ so parameter_overrides reach the node.")
    return not wrong


def _check_behaviour(report: CheckReport, probe: OverheatProbe) -> None:
    if not report.add(f"it publishes its status on status_topic ({STATUS_TOPIC})",
                      poll_until(lambda: probe.latest() is not None, 3.0), "",
                      "Create the publisher with the *value* of status_topic, and a timer at rate_hz."):
        return
    got = probe.latest()
    report.add("before any temperature it reports 'no data'", got == "no data",
               "" if got == "no data" else f"got {got!r}")
    _check_rejections(report, probe)
    for celsius, expected in ((25.0, "ok"), (55.0, "warning"), (85.0, "critical")):
        got = probe.status_after(celsius, expected)
        report.add(f"at {celsius:g} °C (warning_c 50, critical_c 80) it reports {expected!r}",
                   got == expected, "" if got == expected else f"got {got!r}",
                   "Compare the latest temperature with the *current* parameter values in the timer "
                   "callback: >= critical_c is 'critical', >= warning_c is 'warning', else 'ok'.")
    accepted = probe.set_remote("critical_c", 90.0).successful
    got = probe.status_after(None, "warning")
    report.add("after critical_c is set to 90, 85 °C becomes 'warning'", accepted and got == "warning",
               "" if accepted and got == "warning" else
               ("the change was rejected" if not accepted else f"got {got!r}"),
               "Read the thresholds with self.get_parameter(...).value when classifying.")
    default_rate = probe.status_rate()
    report.add("it publishes at about 5 Hz by default", 3.5 <= default_rate <= 6.5,
               "" if 3.5 <= default_rate <= 6.5 else "measured a rate far from 5 Hz")
    accepted = probe.set_remote("rate_hz", 20.0).successful
    fast = probe.status_rate()
    report.add("after rate_hz is set to 20, it publishes at about 20 Hz", accepted and 14.0 <= fast <= 26.0,
               "" if accepted and 14.0 <= fast <= 26.0 else
               ("the change was rejected" if not accepted else "the rate did not follow"),
               "Use add_post_set_parameters_callback to retune: self.timer.timer_period_ns = "
               "int(1e9 / rate_hz).")


def _check_rejections(report: CheckReport, probe: OverheatProbe) -> None:
    result = probe.set_remote("status_topic", "/elsewhere")
    report.add("status_topic is read-only (a change is rejected)", not result.successful, "",
               "ParameterDescriptor(read_only=True)")
    for bad in (0.2, 50.0):
        result = probe.set_remote("rate_hz", bad)
        report.add(f"rate_hz = {bad:g} is rejected (allowed 1.0 to 20.0)",
                   not result.successful and bool(result.reason), "",
                   "ParameterDescriptor(floating_point_range=[FloatingPointRange(from_value=1.0, "
                   "to_value=20.0, step=0.0)])")
    for name, value in (("warning_c", 90.0), ("critical_c", 50.0)):
        result = probe.set_remote(name, value)
        names_both = "warning_c" in result.reason and "critical_c" in result.reason
        report.add(f"{name} = {value:g} is rejected with a reason naming warning_c and critical_c",
                   not result.successful and names_both,
                   "" if not result.successful and names_both else
                   ("accepted" if result.successful else f"reason {result.reason!r}"),
                   "add_on_set_parameters_callback: return SetParametersResult(successful=False, "
                   "reason='warning_c (...) must be below critical_c (...)') when warning_c >= critical_c.")
    probe.set_remote("critical_c", 80.0)  # undo a wrongly accepted change: the next criteria stay meaningful
    result = probe.set_remote("warning_c", 50.0)
    report.add("warning_c = 50 is accepted", result.successful,
               "" if result.successful else f"reason {result.reason!r}",
               "Only reject when warning_c >= critical_c; accept everything else.")
