"""Checkers of chapter 06 (parameters): the configurable overheat monitor, and the conveyor launch.

The launch exercise has two parts, as a real launch test does: a launch description
(``conveyor_launch()``, a list of :class:`NodeLaunch`) and a test that proves the launched nodes
talk (``conveyor_talks(rt)``). :func:`check_conveyor_launch` starts the description with the
course's ``launch()``, reads the parameters back through each node's parameter services, asks
the listener's process whether it hears, and runs the student's proof twice: on the student's
nodes (it must say yes) and on a pair the checker miswires (it must say no).
"""

from __future__ import annotations

from rclpy.node import Node
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from std_msgs.msg import Float64, String

from course_helpers.chapters.ch06_parameters import NodeLaunch, launch
from course_helpers.checks import CheckReport, callback_errors_criterion, student_on_clock
from course_helpers.core.graph_view import NO_ENDPOINTS, endpoints_by_node
from course_helpers.core.runtime import get_runtime
from course_helpers.core.sim_clock import MATCH_TIMEOUT_S
from course_helpers.core.waiting import poll_until

STATUS_TOPIC = "/overheat_check/status"  # the checker's override of status_topic
DEFAULTS = {"rate_hz": 5.0, "warning_c": 60.0, "critical_c": 80.0}
CLOCK_STEP_S = 0.01  # the checker's clock moves in steps this long
STATUS_WITHIN_S = 1.0  # [s of the checker's clock] a status must come this soon (at 1 Hz, the slowest)
RATE_WINDOW_S = 2.0  # [s] the rate is counted over this much of the checker's clock


class OverheatProbe(Node):
    """The checker's side, on the checker's clock: publishes temperatures, records statuses (with the
    clock's time), sets the monitor's parameters through its parameter services."""

    def __init__(self, clock, name: str = "overheat_checker"):
        super().__init__(name)
        self.clock = clock
        self.statuses: list[tuple[float, str]] = []  # (the checker's time [s], status)
        self.status_subscription = self.create_subscription(
            String, STATUS_TOPIC, lambda msg: self.statuses.append((clock.now_s, msg.data)), 50)
        self.temperature = self.create_publisher(Float64, "/temperature", 10)
        self.monitor_parameters = AsyncParameterClient(self, "/overheat_monitor")

    def latest(self) -> str | None:
        """The newest status received, or None."""
        return self.statuses[-1][1] if self.statuses else None

    def set_remote(self, name: str, value):
        """Set one parameter through the monitor's set_parameters service; its SetParametersResult."""
        future = self.monitor_parameters.set_parameters([Parameter(name, value=value)])
        self.clock.settle()  # the request and the answer: both delivered, the callbacks run
        return future.result().results[0]

    def status_after(self, celsius: float | None) -> str | None:
        """Publish a temperature (unless None); the second status after it (the first may come from a
        tick that ran before the monitor took the new temperature), or None if none came within
        ``STATUS_WITHIN_S`` of the checker's clock."""
        before = len(self.statuses)
        if celsius is not None:
            self.temperature.publish(Float64(data=float(celsius)))
            self.clock.settle()
        came = self.clock.advance_until(lambda: len(self.statuses) - before >= 2, 2 * STATUS_WITHIN_S,
                                        CLOCK_STEP_S)
        return self.statuses[-1][1] if came else None

    def statuses_in(self, seconds: float) -> int:
        """How many statuses came over the next ``seconds`` of the checker's clock."""
        start = self.clock.now_s
        self.clock.advance(seconds, CLOCK_STEP_S)
        return sum(t > start for t, _ in self.statuses)


def check_overheat_monitor(node_class, rt=None) -> CheckReport:
    """Exercise 06: set good and bad parameters on ``node_class`` and watch what it publishes.

    ``node_class`` must pass ``**kwargs`` on to Node (the checker overrides status_topic). The monitor
    runs on the checker's clock (:func:`~course_helpers.checks.student_on_clock`): its rate is counted
    in that clock's time, exactly. Returns the CheckReport; ``rt`` defaults to this kernel's runtime.
    """
    rt = rt or get_runtime()
    report = CheckReport("Exercise 06 - configurable overheat monitor")
    overrides = [Parameter("status_topic", value=STATUS_TOPIC)]
    with student_on_clock(report, rt, node_class, "overheat_checker_graph", parameter_overrides=overrides,
                          created="the node can be created with parameter overrides",
                          hint="The exercise's first bullet: what must the constructor take, and pass on "
                               "to Node?") as (node, _graph, clock):
        if node is None:
            return report
        probe = clock.drive(rt.build(OverheatProbe, clock))
        clock.wait_matched()
        if _check_declarations(report, node):
            if report.add("its parameter services answer", _parameter_services_ready(probe, node), "",
                          "Leave start_parameter_services at its default (True): the checker sets "
                          "parameters through them, as `ros2 param set` does."):
                _check_behaviour(report, probe, node)
            callback_errors_criterion(report, clock.errors)
    return report


def _parameter_services_ready(probe: OverheatProbe, node: Node) -> bool:
    """True once the checker's parameter client has matched the monitor's set_parameters service. The
    graph lists this process's own services at once; a listed one matches a moment later."""
    services = node.get_service_names_and_types_by_node(node.get_name(), node.get_namespace())
    if not any(name == f"{node.get_fully_qualified_name()}/set_parameters" for name, _types in services):
        return False
    return poll_until(probe.monitor_parameters.services_are_ready, MATCH_TIMEOUT_S)


def _check_declarations(report: CheckReport, node: Node) -> bool:
    named = node.get_name() == "overheat_monitor"
    if not report.add("the node is called overheat_monitor", named,
                      "" if named else f"it is called {node.get_name()!r}",
                      "The exercise names the node: compare it with the name your constructor passes on."):
        return False
    wrong = []
    for name, default in DEFAULTS.items():
        if not node.has_parameter(name):
            wrong.append(f"{name} is not declared")
        elif (node.get_parameter(name).type_ != Parameter.Type.DOUBLE
              or node.get_parameter(name).value != default):
            wrong.append(f"{name} = {node.get_parameter(name).value!r}")
    report.add("it declares rate_hz = 5.0, warning_c = 60.0 and critical_c = 80.0 (floats)", not wrong,
               "; ".join(wrong), "Compare your names and defaults with the exercise's list; section 2 "
               "explains why 5 and 5.0 are not the same parameter value.")
    if not node.has_parameter("status_topic"):
        report.add("it declares status_topic", False, "", "TODO 1: the exercise lists four parameters.")
        return False
    undescribed = [name for name in ("status_topic", *DEFAULTS)
                   if node.has_parameter(name) and not node.describe_parameter(name).description.strip()]
    report.add("every parameter is declared with a description", not undescribed,
               f"no description: {', '.join(undescribed)}" if undescribed else "",
               "The exercise asks for a description on every parameter; section 2's talker shows where "
               "one goes.")
    report.add("status_topic takes the value given at start (a parameter override)",
               node.get_parameter("status_topic").value == STATUS_TOPIC, "",
               "The exercise's first bullet: the checker's parameter_overrides must reach Node.")
    return not wrong


def _check_behaviour(report: CheckReport, probe: OverheatProbe, node: Node) -> None:
    if not report.add(f"it publishes its status on status_topic ({STATUS_TOPIC})",
                      probe.clock.advance_until(lambda: probe.latest() is not None, STATUS_WITHIN_S,
                                                CLOCK_STEP_S), "",
                      "TODO 3: the publisher's topic is the parameter's value, and a timer publishes."):
        return
    got = probe.latest()
    report.add("before any temperature it reports 'no data'", got == "no data",
               "" if got == "no data" else f"got {got!r}",
               "The exercise says what the status is before the first reading.")
    _check_rejections(report, probe)
    for celsius, expected in ((25.0, "ok"), (55.0, "warning"), (85.0, "critical")):
        got = probe.status_after(celsius)
        report.add(f"at {celsius:g} °C (warning_c 50, critical_c 80) it reports {expected!r}",
                   got == expected, "" if got == expected else f"got {got!r}",
                   "The exercise's timer bullet says which status goes with which temperature.")
    accepted = probe.set_remote("critical_c", 90.0).successful
    got = probe.status_after(None)
    report.add("after critical_c is set to 90, 85 °C becomes 'warning'", accepted and got == "warning",
               "" if accepted and got == "warning" else
               ("the change was rejected" if not accepted else f"got {got!r}"),
               "Does the status use the thresholds as they are now, or as they were at start-up?")
    _check_rate(report, probe, node, "it publishes at 5 Hz by default", 5.0, True,
                "Where does your timer's period come from?")
    accepted = probe.set_remote("rate_hz", 20.0).successful
    _check_rate(report, probe, node, "after rate_hz is set to 20, it publishes at 20 Hz", 20.0,
                accepted, "TODO 2, and section 2's talker: what acts on a change once it is applied?")


def _check_rate(report: CheckReport, probe: OverheatProbe, node: Node, name: str, hz: float, accepted: bool,
                hint: str) -> None:
    """A timer of the node has the period 1/hz (read from the node), and the statuses come hz times a
    second of the checker's clock (counted over ``RATE_WINDOW_S``, give or take one: the window's edges
    fall between ticks). A retuned timer's current period is still the old one (rcl's timer keeps the
    next call it had planned): the count starts at the first status after the change."""
    if not accepted:
        report.add(name, False, "the change was rejected", hint)
        return
    periods_ms = sorted(timer.timer_period_ns / 1e6 for timer in node.timers if not timer.is_canceled())
    timed = any(abs(period - 1e3 / hz) < 0.5 for period in periods_ms)
    before = len(probe.statuses)
    probe.clock.advance_until(lambda: len(probe.statuses) > before, STATUS_WITHIN_S, CLOCK_STEP_S)
    statuses = probe.statuses_in(RATE_WINDOW_S)
    expected = hz * RATE_WINDOW_S
    ok = timed and abs(statuses - expected) <= 1
    report.add(name, ok, "" if ok else
               f"timer periods {', '.join(f'{p:g}' for p in periods_ms) or 'none'} ms, 1/{hz:g} Hz is "
               f"{1e3 / hz:g} ms; {statuses} statuses in {RATE_WINDOW_S:g} s of the checker's clock "
               f"(expected {expected:g})", hint)


def _check_rejections(report: CheckReport, probe: OverheatProbe) -> None:
    result = probe.set_remote("status_topic", "/elsewhere")
    report.add("status_topic is read-only (a change is rejected)", not result.successful, "",
               "Section 2's talker has a parameter that cannot change after start-up.")
    for bad in (0.2, 50.0):
        result = probe.set_remote("rate_hz", bad)
        report.add(f"rate_hz = {bad:g} is rejected (allowed 1.0 to 20.0)",
                   not result.successful and bool(result.reason), "",
                   "Section 2's talker limits its rate with a descriptor field; the exercise gives the "
                   "range.")
    for name, value in (("warning_c", 90.0), ("critical_c", 50.0)):
        result = probe.set_remote(name, value)
        names_both = "warning_c" in result.reason and "critical_c" in result.reason
        report.add(f"{name} = {value:g} is rejected with a reason naming warning_c and critical_c",
                   not result.successful and names_both,
                   "" if not result.successful and names_both else
                   ("accepted" if result.successful else f"reason {result.reason!r}"),
                   "TODO 4, and section 2's validate: compare the proposed value with the current value "
                   "of the other threshold, and say why in the reason.")
    probe.set_remote("critical_c", 80.0)  # undo a wrongly accepted change: the next criteria stay meaningful
    result = probe.set_remote("warning_c", 50.0)
    report.add("warning_c = 50 is accepted", result.successful,
               "" if result.successful else f"reason {result.reason!r}",
               "Your validation rejected a change that keeps warning_c below critical_c.")


# ---------------------------------------------------------------------- exercise 06b: the conveyor launch
CONVEYOR = {  # full name -> (kind, parameters the exercise asks for)
    "/line1/belt_sensor": ("talker", {"topic": "items", "rate_hz": 10.0, "message": "item"}),
    "/line1/counter": ("listener", {"topic": "items", "log_every": 5}),
}
CONVEYOR_TOPIC = "/line1/items"
HANG_S = 30.0  # bounds a hang only: a node answers its parameter services and hears a matched talker in ms
LAUNCH_LABEL = "ex06_conveyor"
MISWIRED_LABEL = "ex06_miswired"


def check_conveyor_launch(describe, proves_they_talk, rt=None) -> CheckReport:
    """Exercise 06b: launch ``describe()`` and run the proof ``proves_they_talk(rt)`` on real nodes.

    ``describe`` returns the launch description (a list of NodeLaunch); ``proves_they_talk`` takes
    the runtime and returns True when /line1/counter hears /line1/belt_sensor. Every process the
    checker starts is stopped before it returns. Returns the CheckReport.
    """
    rt = rt or get_runtime()
    report = CheckReport("Exercise 06b - launch the conveyor and prove it talks")
    entries = report.run("conveyor_launch() returns the launch description", describe,
                         hint="conveyor_launch() returns the kind of list that section 5 passes to launch().")
    if entries is None or not _check_description(report, entries):
        return report
    if not _check_proof_says_no(report, rt, proves_they_talk):
        return report
    group = report.run("the two nodes start together", lambda: launch(entries, label=LAUNCH_LABEL, rt=rt),
                       hint="The error above is the child process's own: compare kinds, names and "
                            "parameter types with the exercise.")
    if group is None:
        return report
    probe = rt.add(Node, "conveyor_checker", console=False)
    try:
        report.add("the two nodes start together", True, ", ".join(group.node_names))
        _check_parameters(report, rt, probe)
        counter = next(child for child, entry in group.members if entry.fqn == "/line1/counter")
        _check_they_talk(report, probe, counter)
        said = _ask_proof(proves_they_talk, rt)
        report.add("your proof says yes for your running nodes", said is True, _said(said),
                   "The exercise's second point lists what the proof looks at, and how it waits for "
                   "discovery.")
    finally:
        rt.remove(probe)
        group.stop()
    return report


def _check_description(report: CheckReport, entries) -> bool:
    if not (isinstance(entries, list) and len(entries) == 2
            and all(isinstance(e, NodeLaunch) for e in entries)):
        got = type(entries).__name__ if not isinstance(entries, list) else f"a list of {len(entries)}"
        return report.add("it describes two nodes as NodeLaunch entries", False, f"got {got}",
                          "Section 5 builds such a list; the exercise describes its two entries.")
    report.add("it describes two nodes as NodeLaunch entries", True)
    try:
        found = {entry.fqn: entry.kind for entry in entries}
    except Exception as error:  # a bad namespace: the entry's own message says what is allowed
        return report.add("the nodes are /line1/belt_sensor (talker) and /line1/counter (listener)", False,
                          str(error), "The exercise gives each node's kind, name and namespace.")
    wanted = {fqn: kind for fqn, (kind, _params) in CONVEYOR.items()}
    return report.add("the nodes are /line1/belt_sensor (talker) and /line1/counter (listener)",
                      found == wanted, "" if found == wanted else f"got {found}",
                      "The exercise gives each node's kind, name and namespace.")


def _string_topics(probe: Node, fqn: str, publishers: bool) -> set[str]:
    """The std_msgs/String topics that node ``fqn`` publishes (or subscribes to), as the graph lists them
    (endpoint by endpoint: a node of the same name that a stopped launch left behind hides nothing)."""
    entry = endpoints_by_node(probe).get(fqn, NO_ENDPOINTS)
    group = entry[0] if publishers else entry[1]
    return {endpoint.split(" ")[0] for endpoint in group if endpoint.endswith(" std_msgs/msg/String")}


def _check_they_talk(report: CheckReport, probe: Node, counter) -> None:
    """The counter hears the belt sensor: both on one topic in the graph, then its process says it heard.

    The graph decides whether they can talk, so a miswired pair fails at once; a pair on one topic
    talks within milliseconds of matching, and HANG_S only bounds a hang.
    """
    criterion = "the counter hears the belt sensor (its process says so)"
    hint = ("Both nodes must resolve to the same topic: a node's namespace and its topic parameter "
            "decide it together.")
    seen: dict[str, set[str]] = {}

    def both_listed() -> bool:
        seen["sends"] = _string_topics(probe, "/line1/belt_sensor", True)
        seen["hears"] = _string_topics(probe, "/line1/counter", False)
        return bool(seen["sends"] and seen["hears"])

    poll_until(both_listed, HANG_S)
    sends, hears = seen["sends"], seen["hears"]
    if not sends & hears:
        report.add(criterion, False, f"the belt sensor publishes on {sorted(sends) or 'nothing'}, "
                   f"the counter listens on {sorted(hears) or 'nothing'}", hint)
        return
    heard = poll_until(lambda: (counter.last("heard") or {}).get("count", 0) >= 1, HANG_S)
    last = (counter.last("heard") or {}).get("last", "")
    said = f"last message heard: {last!r}" if heard else f"it heard nothing on {sorted(sends & hears)}"
    report.add(criterion, heard and last.startswith("item "), said, hint)


def _check_parameters(report: CheckReport, rt, probe: Node) -> None:
    """Read every asked-for parameter back through the node's get_parameters service."""
    wrong = []
    for fqn, (_kind, wanted) in CONVEYOR.items():
        client = AsyncParameterClient(probe, fqn)
        if not client.wait_for_services(HANG_S):
            wrong.append(f"{fqn} offers no parameter services")
            continue
        names = sorted(wanted)
        response = rt.wait_for_future(client.get_parameters(names), HANG_S, f"{fqn}'s parameters")
        for name, value in zip(names, response.values, strict=True):
            got = parameter_value_to_python(value)
            if got != wanted[name] or type(got) is not type(wanted[name]):
                wrong.append(f"{fqn} {name} = {got!r}")
    report.add("the nodes run with the parameters asked for", not wrong, "; ".join(wrong),
               "Compare each node's parameters with the exercise's list, types included (section 2: "
               "10 and 10.0 differ).")


def _check_proof_says_no(report: CheckReport, rt, proves_they_talk) -> bool:
    """Run the proof on a pair that cannot talk (the counter listens on the wrong topic): it must say no."""
    kind_t, talker = CONVEYOR["/line1/belt_sensor"]
    kind_l, counter = CONVEYOR["/line1/counter"]
    miswired = [NodeLaunch(kind_t, "belt_sensor", "/line1", dict(talker)),
                NodeLaunch(kind_l, "counter", "/line1", {**counter, "topic": "items_v2"})]
    group = report.run("the checker's miswired pair starts",
                       lambda: launch(miswired, label=MISWIRED_LABEL, rt=rt))
    if group is None:
        return False
    try:
        said = _ask_proof(proves_they_talk, rt)
    finally:
        group.stop()
        # its nodes leave the graph before the student's nodes (same names) start
        poll_until(lambda: not set(group.node_names) & set(rt.graph_nodes()), HANG_S)
    return report.add("your proof says no when the counter listens on another topic (/line1/items_v2)",
                      said is not True, _said(said),
                      "Messages on the topic alone do not show that the counter hears them: what else does "
                      "the exercise's second point ask the proof to look at?")


def _ask_proof(proves_they_talk, rt):
    """The proof's answer: True/False, or the exception it raised (counted as 'no')."""
    try:
        return proves_they_talk(rt)
    except Exception as error:  # the student's proof gave up (a WaitTimeout, for instance)
        return error


def _said(answer) -> str:
    if isinstance(answer, Exception):
        return f"it raised {type(answer).__name__}: {str(answer).splitlines()[0] if str(answer) else ''}"
    return f"it returned {answer!r}"
