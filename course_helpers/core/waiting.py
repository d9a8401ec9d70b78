"""The one way to wait for something that other threads or processes make true.

``wait_until`` raises :class:`WaitTimeout` naming what it waited for; ``poll_until``
returns False instead, for callers to whom a timeout is an expected outcome (a checker
reports it as a failed criterion).

A wait sleeps until something that can change the answer happens, then checks again. The
package reports those events to :data:`changes`:

* a change of the ROS graph (rcl's graph guard condition, :mod:`.graph_events`);
* a report from a child process, and a child's end (its channel closes, :mod:`.channel`);
* a callback run by an executor that the course spins (:class:`.executors.SpinThread`): a
  message, a timer, a service reply, an event.

A predicate may also read what reports nothing: a thread of the notebook's own, a file, the
clock, a DDS match that follows its graph update by a moment. So a wait also checks every
``period`` seconds (:data:`UNNOTIFIED_PERIOD_S` unless the caller knows better); between events
the waiting thread sleeps and costs no CPU, and the executor keeps the GIL.

A wait for what happens for certain (a reply, a matched talker's message, a node that starts) is
bounded by :data:`HANG_S`: the bound ends a hang and says nothing about speed. A busy machine makes
such a wait longer, never wrong. How fast something happens is a measurement, judged by
:mod:`.verdict`.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from course_helpers.core.errors import WaitTimeout

UNNOTIFIED_PERIOD_S = 0.02  # s; how often a wait looks again when nothing reported a change
MIN_RECHECK_S = 0.005  # s; at most one check per this long, however fast the events come
POLL_PERIOD_S = UNNOTIFIED_PERIOD_S  # the name older callers use
HANG_S = 60.0  # s; the bound on a wait for what happens for certain: it only ends a hang


class Changes:
    """Events that may make a waited-for condition true: a count, and a way to sleep until the next.

    :meth:`notify` is cheap when nobody waits (a counter), so an executor can call it after every
    callback.
    """

    def __init__(self):
        self._count = 0
        self._blocked = 0  # waiters inside wait_past
        self._condition = threading.Condition(threading.Lock())

    @property
    def count(self) -> int:
        """How many events so far: read it before checking a condition, pass it to :meth:`wait_past`."""
        return self._count

    def notify(self) -> None:
        """Something happened: wake every waiter."""
        self._count += 1
        if self._blocked:
            with self._condition:
                self._condition.notify_all()

    def wait_past(self, seen: int, timeout: float) -> None:
        """Sleep until an event after the count ``seen``, or ``timeout`` seconds."""
        with self._condition:
            self._blocked += 1  # before the look at the count: a notify in between still wakes us
            try:
                if self._count == seen:
                    self._condition.wait(timeout)
            finally:
                self._blocked -= 1


changes = Changes()  # the process's events (see the module docstring)


def poll_until(predicate: Callable[[], object], timeout: float, period: float = UNNOTIFIED_PERIOD_S,
               wake_on: Changes | None = changes) -> bool:
    """Check ``predicate()`` until it is true or ``timeout`` seconds pass; True if it came true.

    It is checked again after each event of ``wake_on`` (at most every :data:`MIN_RECHECK_S`) and at
    least every ``period`` seconds; ``wake_on=None`` checks only every ``period``. The predicate is
    checked once more at the deadline, so a short timeout still sees a condition that became true
    meanwhile.
    """
    deadline = time.monotonic() + timeout
    while True:
        seen = wake_on.count if wake_on is not None else 0
        checked = time.monotonic()
        if predicate():
            return True
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return bool(predicate())
        if wake_on is None:
            time.sleep(min(period, remaining))
            continue
        wake_on.wait_past(seen, min(period, remaining))
        pause = MIN_RECHECK_S - (time.monotonic() - checked)
        if pause > 0:
            time.sleep(min(pause, max(0.0, deadline - time.monotonic())))


def wait_until(predicate: Callable[[], object], timeout: float, what: str,
               period: float = UNNOTIFIED_PERIOD_S, wake_on: Changes | None = changes) -> bool:
    """Wait until ``predicate()`` is true; raise :class:`WaitTimeout` saying ``what`` was awaited.

    ``period`` and ``wake_on`` as for :func:`poll_until`.
    """
    if not poll_until(predicate, timeout, period, wake_on):
        raise WaitTimeout(f"timed out after {timeout:g} s waiting for {what}")
    return True


def wait_for_future(future, timeout: float = HANG_S, what: str = "the future"):
    """Wait (without spinning) until an rclpy ``future`` is done (its done callback wakes the wait);
    return its result, or raise its exception. Raises :class:`WaitTimeout` naming ``what``."""
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    if not done.wait(timeout):
        raise WaitTimeout(f"timed out after {timeout:g} s waiting for {what}")
    if future.exception() is not None:
        raise future.exception()
    return future.result()


def sleep_unless(stop: Callable[[], object], seconds: float, period: float = UNNOTIFIED_PERIOD_S) -> bool:
    """Sleep ``seconds`` but wake early when ``stop()`` becomes true; True if stopped early.

    ``period`` is how often ``stop`` is checked besides the events: a longer one costs a busy
    process less.
    """
    return poll_until(stop, seconds, period)
