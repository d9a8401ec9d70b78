"""Chapter 05 (actions), more: the Fibonacci contract and the progress bar's static record, with a real
action server and client over Fast DDS."""

from __future__ import annotations

import sys
from pathlib import Path

from course_interfaces.action import Fibonacci
from rclpy.action import ActionClient, ActionServer
from rclpy.node import Node

from course_helpers.chapters.ch05_actions import FeedbackProgress, sleep_async


class StepwiseFibonacci(Node):
    """The notebook's server in short: F(0) to F(order), one feedback per new term, 0.02 s apart."""

    def __init__(self):
        super().__init__("fib_more_server")
        self.server = ActionServer(self, Fibonacci, "fib_more", self.execute)

    async def execute(self, goal_handle):
        sequence = [0, 1]
        for _ in range(goal_handle.request.order - 1):
            await sleep_async(self, 0.02)
            sequence.append(sequence[-1] + sequence[-2])
            goal_handle.publish_feedback(Fibonacci.Feedback(partial_sequence=sequence))
        goal_handle.succeed()
        return Fibonacci.Result(sequence=sequence)

    def destroy_node(self):
        self.server.destroy()
        super().destroy_node()


def test_installed_fibonacci_definition_says_order_plus_one_terms():
    installed = Path(sys.prefix) / "share" / "course_interfaces" / "action" / "Fibonacci.action"
    text = installed.read_text()
    assert "order + 1 terms" in text and "up to `order` terms" not in text


def test_progress_record_tells_how_the_goal_ended(rt):
    rt.add(StepwiseFibonacci, console=False)
    probe = rt.node("fib_more_probe")
    client = ActionClient(probe, Fibonacci, "fib_more")
    try:
        assert client.wait_for_server(3.0)
        order = 8
        progress = FeedbackProgress(order, lambda feedback: len(feedback.partial_sequence) - 1,
                                    description=f"Fibonacci({order})")
        assert progress.summary() == f"Fibonacci({order}): running after 0 feedback messages"
        handle = rt.wait_for_future(client.send_goal_async(Fibonacci.Goal(order=order),
                                                           feedback_callback=progress.on_feedback), 3.0)
        progress.follow(handle, describe=lambda result: f"{len(result.sequence)} terms")
        outcome = rt.wait_for_future(handle.get_result_async(), 5.0)
        rt.wait_until(lambda: progress.status is not None, 2.0, "the bar to see the end")
    finally:
        rt.remove(probe)
    assert list(outcome.result.sequence) == [0, 1, 1, 2, 3, 5, 8, 13, 21]  # F(0)..F(8): order + 1 terms
    assert progress.values[-1] == order and progress.monotonic
    summary = progress.summary()
    assert summary.startswith(f"Fibonacci({order}): {order + 1} terms, SUCCEEDED after ")
    assert f"after {len(progress.values)} feedback messages" in summary
    page = progress._record_html()
    assert f"<progress value='{order}' max='{order}'>" in page and "SUCCEEDED" in page
