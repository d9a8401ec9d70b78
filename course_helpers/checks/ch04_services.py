"""Checkers of chapter 04 (services): the battery status server and the service that calls a service."""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial

from rclpy.node import Node
from std_msgs.msg import Float32
from std_srvs.srv import Trigger

from course_helpers.chapters.ch04_services import AdderServer, IsolatedExecutor
from course_helpers.checks import (
    CheckReport,
    callback_errors_criterion,
    client_reaches,
    judge_timed_scenario,
    student_on_clock,
)
from course_helpers.core.names import full_name
from course_helpers.core.runtime import get_runtime
from course_helpers.core.sim_clock import MATCH_TIMEOUT_S
from course_helpers.core.validation import interface_name
from course_helpers.core.waiting import poll_until

# (level [%], healthy): 19.6 % is below 20 % although its message rounds it to 20%
BATTERY_CASES = ((57.0, True), (12.4, False), (19.6, False), (20.0, True))
HANG_S = 30.0  # bounds a hang only: a sound server answers in milliseconds, a deadlock never


def offered_services(node: Node) -> dict[str, str]:
    """The services a node object created: resolved name -> type name (read from the node, not the graph)."""
    return {service.service_name: interface_name(service.srv_type) for service in node.services}


class CallbackWatch:
    """Counts the requests a service's callback received and the responses it returned.

    The checker wraps the callback of the student's service with it, so that a request left without
    an answer can say where it stopped: before the student's code, inside it, or after it. The
    wrapper hands every request on unchanged (an async callback is awaited, a plain one called).
    """

    def __init__(self, service):
        from rclpy.executors import await_or_execute

        self.received = 0
        self.returned = 0
        self.group = service.callback_group
        inner = service.callback
        self.name = getattr(inner, "__name__", "callback")

        async def watched(request, response):
            self.received += 1
            answer = await await_or_execute(inner, request, response)
            self.returned += 1
            return answer

        service.callback = watched


@dataclass
class RelayAsked:
    """What came of requests sent to the relay at once: answered, stuck by construction, or not yet."""

    futures: list
    stuck: str = ""  # '' when every request was answered, else why not, in words
    by_construction: bool = True  # False: nothing in the code explains the missing answer (load or DDS may)


@contextmanager
def _client_for_one_attempt(probe: Node, service):
    """A new client of ``service`` on the checker's node, whether it reached the service, and why not;
    destroyed on exit.

    An attempt of a timed scenario sets up its own state (:func:`judge_timed_scenario`), the client
    included: a request lost between one writer and one reader is then never asked again of the same
    pair. A fresh-clone CI run met such a pair once: the client had matched the relay's request reader,
    and three requests, 30 s apart, never reached the relay's callback.
    """
    client = probe.create_client(service.srv_type, service.service_name)
    try:
        yield client, *client_reaches(client, service)
    finally:
        probe.destroy_client(client)


def _ask_relay(box, relay, connect, watch, backend, requests) -> RelayAsked:
    """Send ``requests`` at once, from a client that ``connect()`` makes for this attempt, and wait
    until all are answered, or the relay deadlocks (a callback of ``box`` waits in Client.call(), or
    awaits an answer its own group keeps out: by construction), or a callback raised (its request is
    never answered).
    ``HANG_S`` only bounds a hang of another kind: then the answer says how far the requests got."""
    with connect() as (client, reached, _why):
        if not reached:
            return RelayAsked([], f"the checker's new client did not reach add_via_relay within "
                                  f"{MATCH_TIMEOUT_S:g} s", by_construction=False)
        return _ask_relay_from(box, relay, client, watch, backend, requests)


def _ask_relay_from(box, relay, client, watch, backend, requests) -> RelayAsked:
    received, returned, answered, errors = watch.received, watch.returned, backend.answered, len(box.errors)
    futures = [client.call_async(request) for request in requests]

    def deadlock() -> str:
        waiting = box.waiting_in_a_call()
        if waiting:
            return f"{waiting} waits in client.call() on the only thread that could deliver its answer"
        return _awaits_in_its_own_group(relay, watch)

    poll_until(lambda: all(f.done() for f in futures) or bool(deadlock()) or len(box.errors) > errors,
               HANG_S)
    if all(f.done() for f in futures):
        return RelayAsked(futures)
    if stuck := deadlock():
        return RelayAsked(futures, stuck)
    if len(box.errors) > errors:
        return RelayAsked(futures, "a callback raised an exception, so the request is never answered")
    how_far = (f"your node's callback received {watch.received - received} of {len(requests)} "
               f"request(s) and returned {watch.returned - returned}; the backend answered "
               f"{backend.answered - answered}"
               f"{'' if box.spinning else '; the executor of your node had stopped'}")
    return RelayAsked(futures, f"no answer within {HANG_S:g} s ({how_far})", by_construction=False)


def check_battery_server(node_class, rt=None) -> CheckReport:
    """Exercise 04.1: run ``node_class``; query its ``battery_status`` Trigger service at scripted levels.

    The server runs on the checker's clock (:func:`~course_helpers.checks.student_on_clock`): a
    reading and a call are answered within one settle, so "the answer after this reading" is exact.
    ``node_class`` is the student's class (no constructor arguments), ``rt`` the runtime (default:
    this kernel's). Returns the CheckReport, one criterion per line.
    """
    rt = rt or get_runtime()
    report = CheckReport("Exercise 04.1 - battery status service")
    with student_on_clock(report, rt, node_class, "battery_checker") as (node, probe, clock):
        if node is not None:
            _check_battery(report, node, probe, clock)
            callback_errors_criterion(report, clock.errors)
    return report


def _ask(clock, client):
    """Call the Trigger service and settle: its answer, or None if the server gave none."""
    future = client.call_async(Trigger.Request())
    clock.settle()
    return future.result() if future.done() else None


def _check_battery(report: CheckReport, node: Node, probe: Node, clock) -> None:
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
    service = next(s for s in node.services if s.service_name == "/battery_status")
    reached, why = client_reaches(client, service)
    if not report.add("the checker's client finds the service", reached, why,
                      "The service exists but a default client cannot reach it: did you give it a "
                      "QoS profile of its own?"):
        return
    first = _ask(clock, client)
    if not report.add("it answers before any reading", first is not None,
                      "" if first is not None else "no answer (did the callback return the response?)",
                      "Section 2: what does a service callback give back to rclpy?"):
        return
    report.add("before any reading: success is False and the message says 'no reading'",
               not first.success and "no reading" in first.message.lower(),
               f"got success={first.success}, message={first.message!r}",
               "The exercise's table has a row for the time before the first reading.")
    publisher = probe.create_publisher(Float32, "/battery_level", 10)
    clock.wait_matched()
    if not report.add("it subscribes to /battery_level", publisher.get_subscription_count() >= 1, "",
                      "TODO 1: the exercise names the topic and its message type."):
        return
    for level, healthy in BATTERY_CASES:
        expected = f"{round(level)}%"
        publisher.publish(Float32(data=level))
        clock.settle()
        response = _ask(clock, client)
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
    from the kernel. Its answers are judged as :func:`_check_relay_answers` says: a deadlock decides
    at once, a missing answer on a busy machine is asked again.

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
            service = next(s for s in relay.services
                           if s.service_name == full_name(namespace, "add_via_relay"))
            watch = CallbackWatch(service)
            with _client_for_one_attempt(probe, service) as (_client, ready, why):
                pass  # each attempt below asks from a client of its own
            if not report.add("the checker's client finds the service", ready, why,
                              "The service exists but a default client cannot reach it: did you give it a "
                              "QoS profile of its own?"):
                return report
            backend_service = full_name(namespace, "add_two_ints")
            asks = [c for c in relay.clients if relay.resolve_service_name(c.srv_name) == backend_service]
            backend_seen = bool(asks) and poll_until(lambda: all(c.service_is_ready() for c in asks), HANG_S)
            clients = ", ".join(c.srv_name for c in relay.clients) or "none"
            if not report.add("it has a client of add_two_ints that found the backend", backend_seen,
                              "" if asks else f"its clients: {clients}",
                              "TODO 1: the backend is the add_two_ints service; section 3 shows how a "
                              "node creates a client."):
                return report
            connect = partial(_client_for_one_attempt, probe, service)
            _check_relay_answers(box, report, relay, connect, watch, backend, AddTwoInts)
        finally:
            rt.remove(probe)
            errors = list(box.errors)
    if errors:
        report.add("its callbacks raised no exceptions", False, errors[0])
    return report


DEADLOCK_HINT = ("Section 5 and the exercise's two bullets: why can a callback that waits for another "
                 "service never get its answer on one thread, and what does the client need?")
REMEMBERS_HINT = "Does something your callback keeps on self outlive its own request?"


def _check_relay_answers(box, report, relay, connect, watch, backend, add_two_ints) -> None:
    """Ask the relay for sums, judged by the one timing verdict (:func:`judge_timed_scenario`).

    A deadlock, an exception and a wrong sum are decided by the code, at once. An answer still
    missing after ``HANG_S`` with none of them is not: a request or an answer that DDS has not
    delivered yet on a busy machine looks the same. So, on a busy machine, that step is asked again
    with fresh requests, and reported as inconclusive (with the load) if it still gets no answer.
    """

    def one_sum() -> list[tuple]:
        before = backend.answered
        asked = _ask_relay(box, relay, connect, watch, backend, [add_two_ints.Request(a=2, b=3)])
        if asked.stuck:
            return [("it answers 2 + 3 without a deadlock", False, asked.stuck, DEADLOCK_HINT,
                     asked.by_construction)]
        total = asked.futures[0].result().sum
        asked_backend = backend.answered - before
        return [("it answers 2 + 3 = 5", total == 5, f"got {total}",
                 "Which field of the backend's answer do you copy into your response?", True),
                ("it asked the add_two_ints backend for the sum", asked_backend >= 1,
                 f"the backend answered {asked_backend} request(s)",
                 "The exercise asks the relay to get every sum from add_two_ints.", True)]

    pairs = [(-7, 10), (1000, 234), (0, 0)]

    def three_sums() -> list[tuple]:
        requests = [add_two_ints.Request(a=a, b=b) for a, b in pairs]
        asked = _ask_relay(box, relay, connect, watch, backend, requests)
        if asked.stuck:
            return [("it answers three requests sent at once", False,
                     f"not all were answered: {asked.stuck}", REMEMBERS_HINT, asked.by_construction)]
        sums = [f.result().sum for f in asked.futures]
        return [("it answers three requests sent at once", sums == [a + b for a, b in pairs],
                 f"got {sums}", REMEMBERS_HINT, True)]

    if judge_timed_scenario(report, f"the relay answers 2 + 3 within {HANG_S:g} s", one_sum):
        judge_timed_scenario(report, f"the relay answers three requests sent at once within {HANG_S:g} s",
                             three_sums)


def _awaits_in_its_own_group(relay: Node, watch: CallbackWatch) -> str:
    """Why the relay is deadlocked, in words, while its service callback runs and one of its clients
    waits for an answer in the callback's own mutually exclusive group; '' if none does.

    rclpy's executor holds a callback's group until the callback returns, across every ``await``,
    and runs no other callback of that group meanwhile: the client's answer can never be taken
    while the callback awaits it. A deadlock, by construction, on any executor.
    """
    from rclpy.callback_groups import MutuallyExclusiveCallbackGroup

    if watch.received == watch.returned:
        return ""
    group = watch.group
    if not isinstance(group, MutuallyExclusiveCallbackGroup):
        return ""
    for client in relay.clients:
        if client.callback_group is group and client._pending_requests:  # private: test_rclpy_private_api
            return (f"a deadlock: {relay.get_name()}.{watch.name} awaits an answer that its client "
                    f"{client.srv_name} can only take after the callback returns (they share one mutually "
                    "exclusive callback group)")
    return ""


def _unless(passed: bool, detail: str) -> str:
    return "" if passed else detail
