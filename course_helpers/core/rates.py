"""How often something happens, measured: the rate at which a list grows.

A notebook's measurement of a message rate reads as one call: ``rate_of(listener.heard)`` waits for
the first item (a hang bound only), then counts how many more arrive over ``seconds`` of the wall
clock. It is a measurement: a busy machine delivers fewer, so a cell judges it with
:func:`course_helpers.core.verdict.claim_timing`, never with a bare assertion.
"""

from __future__ import annotations

import time

from course_helpers.core.errors import CourseError
from course_helpers.core.waiting import wait_until

FIRST_ITEM_HANG_S = 30.0  # bounds a hang only: the first message of a running talker comes in milliseconds


def rate_of(items: list, seconds: float = 1.0, what: str = "the first message") -> float:
    """Items per second that ``items`` (a list another thread appends to) gains over ``seconds``,
    counted from its first item on."""
    if not isinstance(seconds, (int, float)) or not 0 < seconds <= 60:
        raise CourseError(f"seconds must be a number from 0 to 60, got {seconds!r}")
    wait_until(lambda: len(items) > 0, FIRST_ITEM_HANG_S, what)
    before, start = len(items), time.monotonic()
    time.sleep(seconds)  # the measurement window itself
    return (len(items) - before) / (time.monotonic() - start)
