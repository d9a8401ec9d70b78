"""Chapters 04-06 (services, actions, parameters): the chapters' helpers, with real nodes over Fast DDS.

The checkers of these chapters are tested in test_ch04_checkers, test_ch05_checkers, test_ch06_checkers and
test_ch06_launch (every criterion against a wrong solution)."""

from __future__ import annotations

import math
import threading
import time
from collections import deque

import pytest
from course_interfaces.action import Navigate
from course_interfaces.srv import AddTwoInts
from rclpy.action import ActionClient, ActionServer
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from course_helpers import CourseError
from course_helpers.chapters.ch04_services import (
    AdderServer,
    IsolatedExecutor,
    Sandbox,
    measure_round_trips,
    spin_until_answered,
)
from course_helpers.chapters.ch05_actions import FeedbackProgress, action_parts, status_name
from course_helpers.chapters.ch06_parameters import (
    NodeLaunch,
    RateTalker,
    RateTuner,
    launch,
    load_parameter_file,
    params_file_arguments,
)
from course_helpers.core.kept_contexts import KEEPER_NODE
from course_helpers.core.node_hook import hook_installed
from course_helpers.core.participants import participant_of
from course_helpers.nodes import Listener, Talker
from course_helpers.solutions.ch05_actions import NavigationServer
from tests.timing import assert_timing

# measures time (rates, latencies, DDS events): make test's timing stage, few workers beside it
pytestmark = pytest.mark.timing


# ---------------------------------------------------------------------- chapter 04: services
class BlockingCaller(Node):
    """Calls add_two_ints synchronously inside a timer callback (deadlocks on one thread)."""

    def __init__(self, callback_group=None, **kwargs):
        super().__init__("blocking_caller", **kwargs)
        self.answer = None
        self.client = self.create_client(AddTwoInts, "add_two_ints", callback_group=callback_group)
        self.timer = self.create_timer(0.05, self.on_timer)

    def on_timer(self):
        if not self.client.service_is_ready():
            return
        self.timer.cancel()
        self.answer = self.client.call(AddTwoInts.Request(a=20, b=22)).sum


class GroupedCaller(BlockingCaller):
    def __init__(self, **kwargs):
        super().__init__(callback_group=MutuallyExclusiveCallbackGroup(), **kwargs)


class AsyncCaller(BlockingCaller):
    def on_timer(self):
        if not self.client.service_is_ready():
            return
        self.timer.cancel()
        future = self.client.call_async(AddTwoInts.Request(a=20, b=22))
        future.add_done_callback(lambda done: setattr(self, "answer", done.result().sum))


class AwaitingCaller(BlockingCaller):
    """An async timer callback that awaits the response; its client in a group of its own or not."""

    def __init__(self, own_group=True, **kwargs):
        super().__init__(callback_group=MutuallyExclusiveCallbackGroup() if own_group else None, **kwargs)

    async def on_timer(self):
        if not self.client.service_is_ready():
            return
        self.timer.cancel()
        self.answer = (await self.client.call_async(AddTwoInts.Request(a=20, b=22))).sum


def deadlock_demo(caller_class, threads=1, timeout_s=2.0, **caller_kwargs):
    """Chapter 04's wiring: one executor spins an adder and the caller, in a sandbox of their own."""
    with Sandbox() as sandbox:
        context = sandbox.context
        executor = (SingleThreadedExecutor(context=context) if threads == 1
                    else MultiThreadedExecutor(num_threads=threads, context=context))
        server = AdderServer(context=context)
        caller = caller_class(context=context, **caller_kwargs)
        executor.add_node(server)
        executor.add_node(caller)
        return spin_until_answered(sandbox, executor, caller, server, timeout_s=timeout_s)


def test_deadlock_demo_reports_the_deadlock_and_leaves_the_runtime_working(rt):
    outcome = deadlock_demo(BlockingCaller, timeout_s=1.0)
    assert outcome.deadlocked
    assert str(outcome) == ("deadlocked: the call did not return within 1 s (BlockingCaller on a "
                            "single-threaded executor; the server never even saw the request)")
    assert deadlock_demo(BlockingCaller, threads=4, timeout_s=1.0).deadlocked
    # the kernel's own executor was never involved: it still delivers messages
    rt.add(Talker, rate_hz=50)
    listener = rt.add(Listener)
    rt.wait_until(lambda: len(listener.heard) >= 3, 5, "messages after the deadlock demo")
    assert [t.name for t in threading.enumerate()].count("isolated-executor") == 0


def test_an_awaiting_callback_whose_client_shares_its_group_never_gets_the_reply(rt):
    outcome = deadlock_demo(AwaitingCaller, own_group=False, timeout_s=1.0)
    assert outcome.deadlocked and outcome.server_answered == 1, str(outcome)
    assert str(outcome).endswith("the server answered, but the reply was never taken)")


class ForeverCaller(Node):
    """Calls a service nobody offers, synchronously, in a timer callback: it would wait forever."""

    def __init__(self):
        super().__init__("forever_caller")
        self.calls = 0
        self.client = self.create_client(AddTwoInts, "nobody_offers_this")
        self.timer = self.create_timer(0.01, self.on_timer)

    def on_timer(self):
        self.calls += 1
        self.client.call(AddTwoInts.Request(a=1, b=2))  # released (None) at teardown, then called again


@pytest.mark.parametrize("executor", ["single", "multi"])
def test_isolated_executor_is_torn_down_although_a_callback_hangs_in_call(rt, executor):
    with IsolatedExecutor(executor, namespace="/hang_test") as box:
        caller = box.add(ForeverCaller)
        assert caller.get_fully_qualified_name() == "/hang_test/forever_caller"
        assert not hook_installed(), "Node.__init__ is rclpy's own again after the build"
        assert box.wait_for(lambda: caller.calls >= 1, 3.0)
        assert not box.wait_for(lambda: caller.calls >= 2, 0.2), "the first call blocks its callback"
        started = time.monotonic()
    assert time.monotonic() - started < 5.0
    assert box.context is None and not box.nodes
    assert "isolated-executor" not in [t.name for t in threading.enumerate()]


class BrokenAfterInit(Node):
    def __init__(self):
        super().__init__("broken_after_init")
        raise RuntimeError("the constructor failed after super().__init__")


def test_isolated_executor_leaves_no_half_built_node(rt):
    with IsolatedExecutor("single", namespace="/broken_test") as box:
        with pytest.raises(RuntimeError, match="constructor failed"):
            box.add(BrokenAfterInit)
        assert not box.nodes and not hook_installed()
    with pytest.raises(CourseError, match="with` block"):
        IsolatedExecutor().add(BrokenAfterInit)


@pytest.mark.parametrize("caller, threads", [(AsyncCaller, 1), (AwaitingCaller, 1), (GroupedCaller, 4)])
def test_fixed_callers_complete(rt, caller, threads):
    outcome = deadlock_demo(caller, threads=threads, timeout_s=10.0)
    assert outcome.completed and outcome.answer == 42, str(outcome)
    assert str(outcome).startswith("completed:")


def test_sandboxes_share_one_kept_participant_and_leave_no_node_behind(rt):
    """A sandbox's nodes go with it; its DDS participant does not (core/kept_contexts.py: destroying a
    participant can hang the process for good), so two sandboxes of one namespace share one."""
    seen = []
    for _ in range(2):
        with IsolatedExecutor("single", namespace="/kept") as box:
            box.add(Talker)
            seen.append((box.context, participant_of(rt, "/kept/talker")))
        rt.wait_until(lambda: "/kept/talker" not in rt.graph_nodes(), 10, "the sandbox's talker to leave")
    (first_context, first), (second_context, second) = seen
    assert second_context is first_context and first_context.ok()
    assert second == first, "each sandbox made a participant of its own"
    # the keeper is a hidden node without endpoints: rmw lists it, rt.graph_nodes() leaves it out
    rt.wait_until(lambda: (KEEPER_NODE, "/kept") in rt.graph.get_node_names_and_namespaces(), 10,
                  "rmw to list the kept participant's keeper")
    assert not [name for name in rt.graph_nodes(include_hidden=True) if name.startswith("/kept/")]
    assert not [(topic, info.node_name) for topic, _types in rt.graph.get_topic_names_and_types()
                for info in rt.graph.get_publishers_info_by_topic(topic) if info.node_name == KEEPER_NODE]


def test_the_sandbox_refuses_what_it_cannot_run(rt):
    with pytest.raises(CourseError, match="IsolatedExecutor|executor must be"):
        IsolatedExecutor("threads")
    with pytest.raises(CourseError, match="`with` block"):
        Sandbox().spin(SingleThreadedExecutor(context=rt.context))
    with Sandbox(namespace="/refusals") as sandbox:
        with pytest.raises(CourseError, match="context=sandbox.context"):
            sandbox.spin(SingleThreadedExecutor(context=rt.context))
        executor = SingleThreadedExecutor(context=sandbox.context)
        with pytest.raises(CourseError, match="timeout_s"):
            spin_until_answered(sandbox, executor, None, None, timeout_s=0)
        sandbox.spin(executor)
        with pytest.raises(CourseError, match="spins an executor already"):
            sandbox.spin(SingleThreadedExecutor(context=sandbox.context))
    assert sandbox.context is None and "isolated-executor" not in [t.name for t in threading.enumerate()]


def test_round_trip_measurement_shows_publish_does_not_wait(rt):
    trips = measure_round_trips(rt, samples=50)
    assert set(trips.samples) == {"publish", "topic_round_trip", "service_round_trip"}
    assert all(len(v) == 50 for v in trips.samples.values())
    # publish() hands the message over and returns; a service call waits for the reply (two messages)
    assert trips.median_us("publish") < trips.median_us("service_round_trip")
    assert "latency_echo" not in rt.children()
    with pytest.raises(CourseError):
        trips.median_us("carrier_pigeon")
    with pytest.raises(CourseError, match="timeout_s"):
        measure_round_trips(rt, samples=10, timeout_s=0)


# ---------------------------------------------------------------------- chapter 05: actions
def test_progress_bar_follows_real_feedback_and_action_parts_are_listed(rt):
    server = rt.add(NavigationServer)
    probe = rt.node("progress_probe")
    client = ActionClient(probe, Navigate, "/navigate")
    try:
        assert client.wait_for_server(3.0)
        parts = action_parts("/navigate", rt)
        assert [(p.kind, p.name.rsplit("/", 1)[-1]) for p in parts] == [
            ("service", "cancel_goal"), ("service", "get_result"), ("service", "send_goal"),
            ("topic", "feedback"), ("topic", "status")]
        progress = FeedbackProgress(1.0, value_of=lambda feedback: feedback.progress)
        goal = Navigate.Goal(speed=1.5)
        goal.target.x = 0.6
        handle = rt.wait_for_future(client.send_goal_async(goal, feedback_callback=progress.on_feedback))
        progress.follow(handle)
        outcome = rt.wait_for_future(handle.get_result_async(), 3.0)
        assert status_name(outcome.status) == "SUCCEEDED"
        rt.wait_until(lambda: progress.status == "SUCCEEDED", 2.0, "the bar to see the end")
        assert progress.monotonic and len(progress.values) >= 3
        assert math.isclose(progress.values[-1], 1.0, abs_tol=0.01)
        assert progress.bar.bar_style == "success"
    finally:
        rt.remove(probe)  # its ActionClient goes with it
        rt.remove(server)
        assert not [w for w in server.waitables if isinstance(w, ActionServer)], "destroy_node cleaned up"
    with pytest.raises(CourseError, match="no action"):
        action_parts("/no_such_action", rt)


# ---------------------------------------------------------------------- chapter 06: parameters
PARAMS_YAML = """
/**:
  ros__parameters:
    message: from the wildcard
    limits:
      max_speed: 1.5
talker:
  ros__parameters:
    rate_hz: 7.5
robot2:
  talker:
    ros__parameters:
      rate_hz: 3.0
      message: robot two
"""


def test_yaml_parameter_file_sets_the_values(rt, tmp_path):
    path = tmp_path / "params.yaml"
    path.write_text(PARAMS_YAML)
    root = {p.name: p.value for p in load_parameter_file(str(path), "talker")}
    assert root == {"message": "from the wildcard", "limits.max_speed": 1.5, "rate_hz": 7.5}
    robot2 = {p.name: p.value for p in load_parameter_file(str(path), "talker", "/robot2")}
    assert robot2["rate_hz"] == 3.0 and robot2["message"] == "robot two"

    node = rt.add(RateTalker, "talker", parameter_overrides=load_parameter_file(str(path), "talker"))
    assert node.get_parameter("rate_hz").value == 7.5
    assert node.get_parameter("message").value == "from the wildcard"
    node = rt.add(RateTalker, "talker", namespace="/robot2", cli_args=params_file_arguments(str(path)))
    assert node.get_parameter("rate_hz").value == 3.0
    assert node.get_parameter("message").value == "robot two"


@pytest.mark.parametrize("text, complaint", [
    ("talker:\n  rate_hz: 2.0\n", "must be a node name"),
    ("talker:\n  ros__parameters:\n    gains: [1, 2.5]\n", "mixes types"),
    ("talker:\n  ros__parameters:\n    gains: []\n", "empty list"),
    ("- just a list\n", "must map node names"),
])
def test_bad_parameter_files_raise_course_errors(tmp_path, text, complaint):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(CourseError, match=complaint):
        load_parameter_file(str(path), "talker")
    with pytest.raises(CourseError, match="not found"):
        load_parameter_file(str(tmp_path / "missing.yaml"), "talker")


def test_rate_tuner_retunes_a_running_node(rt):
    rt.add(RateTalker, "talker", parameter_overrides=[Parameter("rate_hz", value=4.0)])
    tuner = RateTuner("/talker", "chatter", rt=rt)
    assert tuner.get_rate() == 4.0
    assert tuner.set_rate(12.0).successful
    assert_timing("after set_rate(12.0) the talker publishes at 8 to 16 Hz", lambda: tuner.measure(1.0),
                  lambda hz: 8.0 < hz < 16.0, show=lambda hz: f"{hz:.1f} Hz")
    refused = tuner.set_rate(500.0)
    assert not refused.successful and "out of range" in refused.reason
    assert tuner.get_rate() == 12.0


def test_rate_tuner_rate_is_the_talkers_not_the_bursts_of_a_busy_subscriber():
    tuner = RateTuner.__new__(RateTuner)  # only the measuring part: no node needed
    tuner._lock = threading.Lock()
    # ten messages published 0.1 s apart (10 Hz), taken by a stalled subscriber in two bursts
    tuner.arrivals = deque([(5.0 + 0.001 * k, 100.0 + 0.1 * k) for k in range(5)]
                           + [(5.5 + 0.001 * k, 100.5 + 0.1 * k) for k in range(5)])
    assert tuner._rate_between(4.0, 6.0) == pytest.approx(10.0)
    assert tuner._rate_between(5.4, 6.0) == pytest.approx(10.0)  # the window picks by arrival
    assert tuner._rate_between(6.0, 7.0) == 0.0


def test_rate_tuner_widget_draws_outside_the_executor_and_stops_with_its_node(rt, monkeypatch):
    from course_helpers.chapters.ch06_parameters import rate_tuner

    rt.add(RateTalker, "talker", parameter_overrides=[Parameter("rate_hz", value=10.0)])
    tuner = RateTuner("/talker", "chatter", rt=rt)
    tuner.widget()
    assert "rate-tuner-plot" in [t.name for t in threading.enumerate()]
    drawn_in = []  # the thread of each redraw from now on
    draw = tuner._refresh_widgets

    def noting_the_thread():
        drawn_in.append(threading.current_thread().name)
        draw()

    monkeypatch.setattr(tuner, "_refresh_widgets", noting_the_thread)
    assert_timing("the talker keeps its 10 Hz (7 to 13 Hz) while the plot is redrawn",
                  lambda: tuner.measure(2.0), lambda hz: 7.0 < hz < 13.0, show=lambda hz: f"{hz:.1f} Hz")
    # the redraws (one a second) ran in the drawing thread, never in the executor thread that runs the
    # talker's timer (an event, not a time: true however slow the drawing is)
    assert drawn_in and set(drawn_in) == {"rate-tuner-plot"}, drawn_in
    assert bytes(tuner._widgets[2].value).startswith(b"\x89PNG")
    rt.remove(tuner.node)
    # destroying the node wakes the drawing thread, which ends and says so in the widget (an event:
    # the default bound only ends a hang)
    rt.wait_until(lambda: "rate-tuner-plot" not in [t.name for t in threading.enumerate()],
                  what="the drawing thread to end after its node was removed")
    slider, label, _image = tuner._widgets
    assert slider.disabled and label.value == rate_tuner.NODE_GONE_NOTE
    tuner._on_slider(5.0, label)  # a slider move after that is refused in the cell, not sent
    assert label.value == rate_tuner.NODE_GONE_NOTE and tuner.requested == 10.0


def test_launch_starts_configured_nodes_and_stops_them_together(rt, tmp_path):
    path = tmp_path / "robots.yaml"
    path.write_text("/**:\n  ros__parameters:\n    message: launched\n")
    group = launch([
        NodeLaunch("talker", "talker", namespace="/r1", params_file=str(path),
                   parameters={"rate_hz": 20.0}),
        NodeLaunch("listener", "listener", namespace="/r1", parameters={"log_every": 2}),
    ], label="testlaunch", rt=rt)
    try:
        assert group.alive and group.node_names == ["/r1/listener", "/r1/talker"]
        heard = rt.wait_for_messages("/r1/chatter", "std_msgs/msg/String", count=2, timeout=5.0)
        assert heard[0].data.startswith("launched ")
    finally:
        codes = group.stop()
    assert set(codes) == {"/r1/listener", "/r1/talker"}
    assert not group.alive
    # a lost goodbye packet leaves a node in the graph until its discovery lease (20 s) runs out
    rt.wait_until(lambda: not {"/r1/listener", "/r1/talker"} & set(rt.graph_nodes()), 30,
                  "the launched nodes to leave the graph")
    with pytest.raises(CourseError, match="share a name"):
        launch([NodeLaunch("talker", "a"), NodeLaunch("listener", "a")], rt=rt)


def test_launch_reports_a_node_that_fails_to_start_and_leaves_nothing_running(rt, tmp_path):
    path = tmp_path / "wrong.yaml"
    path.write_text("talker:\n  ros__parameters:\n    rate_hz: fast\n")  # a string for a double
    with pytest.raises(CourseError, match="exited with code 1 before the start of node /talker") as error:
        launch([NodeLaunch("listener", "listener"), NodeLaunch("talker", "talker", params_file=str(path))],
               label="brokenlaunch", rt=rt)
    assert "rate_hz" in str(error.value)  # the child's own error, from its output
    assert not [name for name in rt.children() if name.startswith("brokenlaunch__")]
