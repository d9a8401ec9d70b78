"""The one way to wait for something that other threads or processes make true.

``wait_until`` raises :class:`WaitTimeout` naming what it waited for; ``poll_until``
returns False instead, for callers to whom a timeout is an expected outcome (a checker
reports it as a failed criterion). Both check the predicate every few milliseconds and
sleep in between, so the waiting thread costs no CPU and the executor keeps the GIL.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from course_helpers.core.errors import WaitTimeout

POLL_PERIOD_S = 0.005


def poll_until(predicate: Callable[[], object], timeout: float,
               period: float = POLL_PERIOD_S) -> bool:
    """Check ``predicate()`` until it is true or ``timeout`` seconds pass; True if it came true.

    The predicate is checked once more at the deadline, so a short timeout still sees a
    condition that became true while sleeping.
    """
    deadline = time.monotonic() + timeout
    while True:
        if predicate():
            return True
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return bool(predicate())
        time.sleep(min(period, remaining))


def wait_until(predicate: Callable[[], object], timeout: float, what: str) -> bool:
    """Wait until ``predicate()`` is true; raise :class:`WaitTimeout` saying ``what`` was awaited."""
    if not poll_until(predicate, timeout):
        raise WaitTimeout(f"timed out after {timeout:g} s waiting for {what}")
    return True


def sleep_unless(stop: Callable[[], object], seconds: float, period: float = POLL_PERIOD_S) -> bool:
    """Sleep ``seconds`` but wake early when ``stop()`` becomes true; True if stopped early.

    ``period`` is how often ``stop`` is checked: a longer one costs a busy process less.
    """
    return poll_until(stop, seconds, period)
