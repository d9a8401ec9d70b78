"""A goal sent from the notebook's thread finds its response, however early the executor takes it.

``core/action_requests.py`` puts each ``ActionClient``'s send-and-file and its ``take_data`` under
one lock (ros2/rclpy#1123). The race needs the executor thread to take the response while the
sending thread is between ``send_goal_request`` and filing the sequence number, which happens
now and then on a busy machine. These tests make it happen every time, with no sleep: the client's
rcl handle (``ActionClient._client_handle``, private, used only here) is wrapped so that
``send_goal_request`` returns only when the executor has reached the response. One test shows
rclpy's own order losing the goal, so the lock is seen to be what keeps it.
"""

from __future__ import annotations

import threading

import pytest
from course_interfaces.action import Fibonacci
from rclpy.action import ActionClient, ActionServer
from rclpy.node import Node

from course_helpers.core.action_requests import unlocked

ACTION = "goal_race"
BOUND_S = 10.0  # how long a send waits for the executor to reach the response; not a timing verdict


class OneStepFibonacci(Node):
    def __init__(self):
        super().__init__("goal_race_server")
        self.server = ActionServer(self, Fibonacci, ACTION, self.execute)

    def execute(self, goal_handle):
        goal_handle.succeed()
        return Fibonacci.Result(sequence=[0, 1])

    def destroy_node(self):
        self.server.destroy()
        super().destroy_node()


class SendWaitsFor:
    """The client's rcl handle, whose ``send_goal_request`` returns only once ``event`` is set."""

    def __init__(self, handle, event: threading.Event):
        self._handle = handle
        self._event = event
        self.reached_in_time: bool | None = None

    def send_goal_request(self, request):
        sequence_number = self._handle.send_goal_request(request)
        self.reached_in_time = self._event.wait(BOUND_S)
        return sequence_number

    def __getattr__(self, name):
        return getattr(self._handle, name)

    def __enter__(self):
        return self._handle.__enter__()

    def __exit__(self, *exc_info):
        return self._handle.__exit__(*exc_info)


class RacingClient:
    """An action client whose executor reaches each goal response before the send has returned."""

    def __init__(self, rt, take_data, wait_for: str):
        rt.add(OneStepFibonacci, console=False)
        self.rt = rt
        self.node = rt.node("goal_race_client")
        self.client = ActionClient(self.node, Fibonacci, ACTION)
        self.take_started = threading.Event()  # the executor is taking a goal response
        self.goal_executed = threading.Event()  # ... and has handed it to the client's execute
        client = self.client

        def spy_take_data():
            if client._is_goal_response_ready:
                self.take_started.set()
            return take_data(client)

        async def spy_execute(taken):
            await ActionClient.execute(client, taken)
            if "goal" in taken:
                self.goal_executed.set()

        client.take_data = spy_take_data
        client.execute = spy_execute
        self.handle = SendWaitsFor(client._client_handle,
                                   self.take_started if wait_for == "take" else self.goal_executed)
        client._client_handle = self.handle

    def close(self):
        self.client.destroy()
        self.rt.remove(self.node)


@pytest.fixture
def racing(rt):
    made = []

    def make(take_data, wait_for):
        made.append(RacingClient(rt, take_data, wait_for))
        assert made[-1].client.wait_for_server(5.0), "the goal_race server was not found"
        return made[-1]

    yield make
    for racer in made:
        racer.close()


def test_a_goal_response_taken_while_the_send_runs_still_completes_the_future(rt, racing):
    racer = racing(ActionClient.take_data, wait_for="take")
    future = racer.client.send_goal_async(Fibonacci.Goal(order=1))
    assert racer.handle.reached_in_time, "the executor never began to take the goal response"
    goal = rt.wait_for_future(future, 5.0, "the goal's acceptance")
    assert goal.accepted


def test_rclpys_own_order_drops_a_goal_response_taken_while_the_send_runs(rt, racing):
    probe = ActionClient(rt.graph, Fibonacci, "goal_race_probe")
    locks_itself = hasattr(probe, "_lock")
    probe.destroy()
    if locks_itself:
        pytest.skip("this rclpy locks its action client itself (ros2/rclpy#1308): "
                    "core/action_requests.py can go")
    racer = racing(unlocked("take_data"), wait_for="execute")
    future = unlocked("send_goal_async")(racer.client, Fibonacci.Goal(order=1))
    assert racer.handle.reached_in_time, "the executor never handed the goal response to the client"
    assert not future.done()  # its response came and went: this future would never complete
