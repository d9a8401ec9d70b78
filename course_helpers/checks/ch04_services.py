"""Checkers of chapter 04 (services): the battery status server and the service that calls a service."""

from __future__ import annotations

from rclpy.node import Node
from std_msgs.msg import Float32
from std_srvs.srv import Trigger

from course_helpers.chapters.ch04_services import AdderServer, IsolatedExecutor
from course_helpers.checks import CheckReport, student_node
from course_helpers.core.names import full_name
from course_helpers.core.runtime import get_runtime
from course_helpers.core.validation import interface_name
from course_helpers.core.waiting import poll_until

ANSWER_TIMEOUT_S = 2.0


def offered_services(node: Node) -> dict[str, str]:
    """The services a node object created: resolved name -> type name (read from the node, not the graph)."""
    return {service.service_name: interface_name(service.srv_type) for service in node.services}


def _call(rt, client, request, timeout_s: float = ANSWER_TIMEOUT_S):
    return rt.wait_for_future(client.call_async(request), timeout_s, f"an answer from {client.srv_name}")


def check_battery_server(node_class, rt=None) -> CheckReport:
    """Exercise 04.1: run ``node_class``; query its ``battery_status`` Trigger service at scripted levels.

    ``node_class`` is the student's class (no constructor arguments), ``rt`` the runtime
    (default: this kernel's). Returns the CheckReport, one criterion per line.
    """
    rt = rt or get_runtime()
    report = CheckReport("Exercise 04.1 - battery status service")
    with student_node(report, rt, node_class, "battery_checker") as (node, probe):
        if node is not None:
            _check_battery(rt, report, node, probe)
    return report


def _check_battery(rt, report: CheckReport, node: Node, probe: Node) -> None:
    if not report.add("the node is called battery_monitor", node.get_name() == "battery_monitor",
                      _unless(node.get_name() == "battery_monitor", f"it is called {node.get_name()!r}"),
                      "The exercise names the node: compare it with the name your constructor passes on."):
        return
    offered = offered_services(node).get("/battery_status")
    if not report.add("it offers /battery_status of type std_srvs/srv/Trigger",
                      offered == "std_srvs/srv/Trigger",
                      f"it offers {offered}" if offered else "it offers no /battery_status service",
                      "TODO 2: the exercise names the service and its type; section 2's server shows "
                      "how a node offers one."):
        return
    client = probe.create_client(Trigger, "/battery_status")
    if not report.add("the checker's client finds the service", poll_until(client.service_is_ready, 3.0),
                      "", "The service exists but a default client cannot reach it: did you give it a "
                          "QoS profile of its own?"):
        return
    first = report.run("it answers before any reading", lambda: _call(rt, client, Trigger.Request()),
                       hint="Section 2: what does a service callback give back to rclpy?")
    if first is None:
        return
    report.add("before any reading: success is False and the message says 'no reading'",
               not first.success and "no reading" in first.message.lower(),
               f"got success={first.success}, message={first.message!r}",
               "The exercise's table has a row for the time before the first reading.")
    publisher = probe.create_publisher(Float32, "/battery_level", 10)
    if not report.add("it subscribes to /battery_level", poll_until(
            lambda: publisher.get_subscription_count() >= 1, 3.0), "",
            "TODO 1: the exercise names the topic and its message type."):
        return
    for level, healthy in ((57.0, True), (12.4, False), (20.0, True)):
        expected = f"{round(level)}%"
        publisher.publish(Float32(data=level))
        response = _answer_when(rt, client, lambda r, text=expected: text in r.message)
        if response is None or expected not in response.message:
            got = response.message if response is not None else "no answer"
            report.add(f"after a reading of {level:g}%: the message contains '{expected}'", False,
                       f"message {got!r}", "The table's messages give the latest level, rounded to a "
                                           "whole percent.")
            continue
        low_ok = ("low" in response.message.lower()) == (not healthy)
        report.add(f"after a reading of {level:g}%: success is {healthy} and the message is "
                   f"{'a low-battery warning' if not healthy else 'not a warning'}",
                   response.success == healthy and low_ok,
                   f"got success={response.success}, message={response.message!r}",
                   "Compare your answer with the exercise's table for this level; mind the boundary "
                   "at 20 %.")


def check_relay_server(node_class, rt=None) -> CheckReport:
    """Exercise 04.2: ``node_class`` answers ``add_via_relay`` by calling ``add_two_ints``, without deadlock.

    The node runs next to a reference adder on a single-threaded executor of its
    own (so a deadlock cannot freeze the kernel); the checker's client calls it
    from the kernel.

    Takes and returns the same as :func:`check_battery_server`.
    """
    from course_interfaces.srv import AddTwoInts

    rt = rt or get_runtime()
    report = CheckReport("Exercise 04.2 - a service that calls a service")
    namespace = "/relay_check"
    with IsolatedExecutor("single", namespace=namespace) as box:
        backend = box.add(AdderServer)
        relay = report.run("the node can be created", lambda: box.add(node_class),
                           hint="Run the class cell first; the constructor must take no arguments.")
        if relay is None:
            return report
        probe = rt.add(Node, "relay_checker", console=False)
        try:
            named = relay.get_name() == "sum_relay"
            if not report.add("the node is called sum_relay", named,
                              _unless(named, f"it is called {relay.get_name()!r}"),
                              "The exercise names the node: compare it with the name your constructor "
                              "passes on."):
                return report
            offered = offered_services(relay).get(full_name(namespace, "add_via_relay"))
            if not report.add("it offers add_via_relay of type course_interfaces/srv/AddTwoInts",
                              offered == "course_interfaces/srv/AddTwoInts",
                              f"it offers {offered}" if offered else "it offers no add_via_relay service",
                              "TODO 2: the exercise names the service; its type is the backend's."):
                return report
            client = probe.create_client(AddTwoInts, full_name(namespace, "add_via_relay"))
            ready = poll_until(client.service_is_ready, 3.0)
            if not report.add("the checker's client finds the service", ready, "",
                              "The service exists but a default client cannot reach it: did you give it a "
                              "QoS profile of its own?"):
                return report
            backend_seen = poll_until(lambda: bool(relay.clients) and all(
                c.service_is_ready() for c in relay.clients), 3.0)
            if not report.add("it has a client of add_two_ints that found the backend", backend_seen, "",
                              "TODO 1: the backend is the add_two_ints service; section 3 shows how a "
                              "node creates a client."):
                return report
            _check_relay_answers(rt, report, client, backend, AddTwoInts)
        finally:
            rt.remove(probe)
            errors = list(box.errors)
    if errors:
        report.add("its callbacks raised no exceptions", False, errors[0])
    return report


def _check_relay_answers(rt, report, client, backend, add_two_ints) -> None:
    before = backend.answered
    try:
        response = _call(rt, client, add_two_ints.Request(a=2, b=3))
    except TimeoutError:
        report.add(f"it answers 2 + 3 within {ANSWER_TIMEOUT_S:g} s", False,
                   "no answer: the callback is stuck waiting (deadlock)",
                   "Section 5 and the exercise's two bullets: why can a callback that waits for "
                   "another service never get its answer on one thread, and what does the client need?")
        return
    report.add("it answers 2 + 3 = 5", response.sum == 5, f"got {response.sum}",
               "Which field of the backend's answer do you copy into your response?")
    report.add("it asked the add_two_ints backend for the sum", backend.answered == before + 1,
               f"the backend answered {backend.answered - before} request(s)",
               "The exercise asks the relay to get every sum from add_two_ints.")
    pairs = [(-7, 10), (1000, 234), (0, 0)]
    futures = [client.call_async(add_two_ints.Request(a=a, b=b)) for a, b in pairs]
    try:
        sums = [rt.wait_for_future(f, ANSWER_TIMEOUT_S, "the relayed sums").sum for f in futures]
    except TimeoutError:
        report.add("it answers three requests sent at once", False, "not all were answered in time",
                   "Does something your callback keeps on self outlive its own request?")
        return
    report.add("it answers three requests sent at once", sums == [a + b for a, b in pairs],
               f"got {sums}", "Does something your callback keeps on self outlive its own request?")


def _unless(passed: bool, detail: str) -> str:
    return "" if passed else detail


def _answer_when(rt, client, accept, timeout_s: float = 1.5):
    """Call the Trigger service until ``accept(response)`` or ``timeout_s`` passes.

    Returns the last response, or None if none came (a call unanswered within 1 s ends
    the asking).
    """
    answers = []

    def accepted() -> bool:
        try:
            answers.append(_call(rt, client, Trigger.Request(), 1.0))
        except TimeoutError:
            return True  # the service stopped answering: stop asking
        return accept(answers[-1])

    poll_until(accepted, timeout_s, period=0.02)
    return answers[-1] if answers else None
