"""Waits sleep until something can have changed: events wake them, the graph is asked once per change.

Real rclpy over real Fast DDS: the graph events come from rcl's graph guard condition.
"""

from __future__ import annotations

import threading
import time

from course_helpers.core import waiting
from course_helpers.core.names import node_full_names
from course_helpers.nodes import make_talker

from .helpers_children import report_after


def test_a_wait_wakes_on_an_event_not_at_its_period():
    events = waiting.Changes()
    flag = threading.Event()

    def later():
        time.sleep(0.2)
        flag.set()
        events.notify()

    threading.Thread(target=later, daemon=True).start()
    started = time.monotonic()
    assert waiting.poll_until(flag.is_set, 30, period=60, wake_on=events)
    assert time.monotonic() - started < 10, "the wait slept through the event until its deadline"


def test_a_wait_without_events_still_looks_every_period():
    flag = threading.Event()
    threading.Timer(0.2, flag.set).start()  # sets the flag and notifies nothing
    started = time.monotonic()
    assert waiting.poll_until(flag.is_set, 30, period=0.05, wake_on=waiting.Changes())
    assert time.monotonic() - started < 10


def _count_calls(obj, name: str) -> list[int]:
    """Count the calls of ``obj.name`` from now on (the real method still runs)."""
    calls = [0]
    real = getattr(obj, name)

    def counted(*args, **kwargs):
        calls[0] += 1
        return real(*args, **kwargs)

    setattr(obj, name, counted)
    return calls


def test_a_graph_wait_asks_rcl_once_per_change_not_on_every_look(rt):
    """A 3 s wait for a node that never comes, with the graph still: a handful of rcl graph queries
    (the 5 ms polling before asked hundreds of times)."""
    graph = rt._graph_view()
    rt.graph_nodes()
    calls = _count_calls(graph.node, "get_node_names_and_namespaces")
    try:
        assert not rt.poll_until(lambda: "/never_there" in rt.graph_nodes(), 3.0)
    finally:
        del graph.node.get_node_names_and_namespaces  # the instance attribute: the class method again
    assert calls[0] <= 20, f"{calls[0]} graph queries during a 3 s wait on a still graph"


def test_the_graph_answers_follow_every_change(rt):
    """Cached answers equal what rcl says right now, after nodes came and went."""
    names = [f"cache_talker_{i}" for i in range(3)]
    for name in names:
        rt.spawn(name, make_talker, params={"name": name}, wait_for=f"/{name}")
    assert {f"/{n}" for n in names} <= set(rt.graph_nodes())
    rt.stop_children(names[:2])
    left = {f"/{n}" for n in names[:2]}
    rt.wait_until(lambda: not left & set(rt.graph_nodes()), 10, "two talkers to leave")
    fresh = node_full_names(rt._graph_view().node.get_node_names_and_namespaces())
    assert f"/{names[2]}" in rt.graph_nodes() and f"/{names[2]}" in fresh
    assert set(rt.graph_nodes()) <= set(fresh)


def test_a_wait_for_a_childs_report_is_woken_by_the_report(rt):
    """The report arrives 2 s after the start: the wait looks a few times, not every few milliseconds."""
    child = rt.spawn("late_reporter", report_after, params={"delay_s": 2.0})
    calls = _count_calls(child.channel, "last")
    started = time.monotonic()
    assert child.wait_for_report("late", 30) == {"after_s": 2.0}
    assert time.monotonic() - started < 20
    assert calls[0] <= 15, f"{calls[0]} looks at the reports while waiting 2 s for one"


def test_a_spawn_asks_the_graph_a_few_times(rt):
    graph = rt._graph_view()
    calls = _count_calls(graph.node, "get_node_names_and_namespaces")
    try:
        child = rt.spawn("woken_talker", make_talker, params={"name": "woken_talker"},
                         wait_for="/woken_talker")
    finally:
        del graph.node.get_node_names_and_namespaces
    assert child.alive and "/woken_talker" in rt.graph_nodes()
    assert calls[0] <= 15, f"{calls[0]} graph queries while one child came up"
