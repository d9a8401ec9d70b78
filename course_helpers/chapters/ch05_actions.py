"""Chapter 05 (actions): pauses that do not block, a feedback progress bar, an action's parts.

* :func:`sleep_async` is an awaitable pause for ``async def`` callbacks (an action's
  execute callback): it lets the single executor thread run other callbacks
  meanwhile, where ``time.sleep`` would freeze every node of the kernel.
* :class:`FeedbackProgress` drives the course's progress bar
  (:class:`~course_helpers.notebook.progress.ProgressWithRecord`) with an action client's
  feedback callback and keeps the values it saw; in a notebook it leaves a static record
  of how the goal ended.
* :func:`action_parts` lists, from the live graph, the hidden topics and services
  an action is made of (``<action>/_action/feedback``, ``.../status``,
  ``.../send_goal``, ``.../cancel_goal``, ``.../get_result``).
"""

from __future__ import annotations

import html
from collections.abc import Callable
from dataclasses import dataclass

from action_msgs.msg import GoalStatus
from rclpy.node import Node
from rclpy.task import Future

from course_helpers.core.errors import CourseError
from course_helpers.core.names import as_full_name
from course_helpers.core.runtime import get_runtime
from course_helpers.core.validation import check_topic_name

STATUS_NAMES = {
    GoalStatus.STATUS_UNKNOWN: "UNKNOWN",
    GoalStatus.STATUS_ACCEPTED: "ACCEPTED",
    GoalStatus.STATUS_EXECUTING: "EXECUTING",
    GoalStatus.STATUS_CANCELING: "CANCELING",
    GoalStatus.STATUS_SUCCEEDED: "SUCCEEDED",
    GoalStatus.STATUS_CANCELED: "CANCELED",
    GoalStatus.STATUS_ABORTED: "ABORTED",
}


def status_name(status: int) -> str:
    """The name of a GoalStatus code: ``status_name(4) == 'SUCCEEDED'``."""
    return STATUS_NAMES.get(status, f"status {status}")


def sleep_async(node: Node, seconds: float) -> Future:
    """Return a future that completes after ``seconds``; ``await`` it in an ``async def`` callback.

    rclpy has no awaitable sleep. This one uses a one-shot timer of ``node``: while
    the callback waits, the executor thread is free to run every other callback
    (other goals, cancel requests, other nodes' timers).
    """
    if not isinstance(seconds, (int, float)) or seconds < 0:
        raise CourseError(f"seconds must be a number >= 0, got {seconds!r}")
    done = Future()

    def wake():
        node.destroy_timer(timer)
        if not done.done():
            done.set_result(None)

    timer = node.create_timer(max(seconds, 1e-6), wake)
    return done


class FeedbackProgress:
    """A progress bar fed by action feedback: pass ``progress.on_feedback`` as ``feedback_callback``.

    ``value_of(feedback)`` turns one feedback message (the ``.feedback`` field of
    what the client receives) into a number from 0 to ``maximum``. Every value is
    kept in ``values``; :meth:`follow` colours the bar when the goal ends (green
    succeeded, orange canceled, red aborted). Displayed in a notebook, the bar comes
    with a static record (``notebook.records``) that :meth:`follow` fills in with the
    outcome, so a saved notebook shows how the goal ended, not an empty bar.
    """

    def __init__(self, maximum: float, value_of: Callable, description: str = "progress"):
        if not isinstance(maximum, (int, float)) or maximum <= 0:
            raise CourseError(f"maximum must be a number > 0, got {maximum!r}")
        if not callable(value_of):
            raise CourseError("value_of must be a function: feedback -> number, e.g. "
                              "lambda fb: len(fb.partial_sequence)")
        from course_helpers.notebook.progress import ProgressWithRecord

        self.maximum = maximum
        self.value_of = value_of
        self.description = description
        self.values: list[float] = []
        self.status: str | None = None
        self.outcome_text = ""
        self.progress = ProgressWithRecord(description, maximum, f"0 / {maximum:g}", describe=True)
        self.bar, self.label, self.widget = self.progress.bar, self.progress.label, self.progress.widget

    @property
    def record(self):
        """The static record, once the bar is displayed (else None)."""
        return self.progress.record

    def on_feedback(self, feedback_message) -> None:
        """Feedback callback for ``ActionClient.send_goal_async``: move the bar."""
        value = float(self.value_of(feedback_message.feedback))
        self.values.append(value)
        self.progress.move(value, f"{value:g} / {self.maximum:g}")

    def follow(self, goal_handle, describe: Callable | None = None) -> None:
        """Colour the bar and show the final status when the goal's result arrives.

        ``describe(result)`` (optional) turns the result message into a few words for the
        record, e.g. ``lambda result: f'{len(result.sequence)} terms'``.
        """
        def finished(future):
            outcome = future.result()
            self.status = status_name(outcome.status) if outcome is not None else "UNKNOWN"
            self.progress.end({"SUCCEEDED": "success", "CANCELED": "warning"}.get(self.status, "danger"),
                              f"{self.label.value}  {self.status}")
            if describe is not None and outcome is not None:
                self.outcome_text = str(describe(outcome.result))
            self.progress.update_record(self.summary(), self._record_html())

        goal_handle.get_result_async().add_done_callback(finished)

    def summary(self) -> str:
        """One line: the goal's outcome so far, e.g. 'Fibonacci(15): 16 terms, SUCCEEDED after
        14 feedback messages (last value 15 of 15)'."""
        what = f"{self.outcome_text}, " if self.outcome_text else ""
        state = self.status or "running"
        last = f" (last value {self.values[-1]:g} of {self.maximum:g})" if self.values else ""
        return f"{self.description}: {what}{state} after {len(self.values)} feedback messages{last}"

    def _record_html(self) -> str:
        value = min(max(self.values[-1], 0.0), float(self.maximum)) if self.values else 0.0
        return (f"<progress value='{value:g}' max='{self.maximum:g}'></progress> "
                f"<code>{html.escape(self.summary())}</code>")

    @property
    def monotonic(self) -> bool:
        """True if the values never went down."""
        return all(a <= b for a, b in zip(self.values, self.values[1:], strict=False))

    def _ipython_display_(self):
        self.progress.show(self.summary(), self._record_html())


@dataclass(frozen=True)
class ActionPart:
    """One topic or service an action is made of."""

    kind: str  # 'topic' or 'service'
    name: str
    type: str
    role: str


_ROLES = {
    "send_goal": "client asks the server to accept a goal",
    "cancel_goal": "client asks to cancel goals",
    "get_result": "client asks for a goal's result (answered when it ends)",
    "feedback": "server streams feedback for each goal",
    "status": "server publishes the status of every goal",
}


def action_parts(action_name: str, rt=None) -> list[ActionPart]:
    """The hidden topics and services behind ``action_name`` ('/fibonacci' or 'fibonacci').

    Read from the live graph of ``rt`` (default: this kernel's runtime). Returns the
    :class:`ActionPart` list sorted by kind and name; raises :class:`CourseError` if the
    graph has no such action.
    """
    check_topic_name(action_name)
    name = as_full_name(action_name)
    rt = rt or get_runtime()
    prefix = f"{name}/_action/"
    parts = []
    for kind, entries in (("topic", rt.graph.get_topic_names_and_types()),
                          ("service", rt.graph.get_service_names_and_types())):
        for entity, types in entries:
            if entity.startswith(prefix):
                suffix = entity[len(prefix):]
                parts.append(ActionPart(kind, entity, ", ".join(types), _ROLES.get(suffix, "")))
    if not parts:
        raise CourseError(f"no action {name} in the graph (is its server running?); "
                          "`%ros2 action list` shows the actions there are")
    return sorted(parts, key=lambda p: (p.kind, p.name))


def print_action_parts(action_name: str, rt=None) -> None:
    """Print :func:`action_parts` of ``action_name`` as an aligned table, one part per line."""
    for part in action_parts(action_name, rt):
        print(f"{part.kind:<8} {part.name:<34} {part.type:<51} {part.role}")
