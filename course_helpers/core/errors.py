"""Errors raised by the course helpers (every chapter).

Each error says what was wrong and what is allowed, so a student can fix the
cell and carry on; the runtime keeps working after any of them.
"""


class CourseError(ValueError):
    """Bad input to a course helper: the message names the value and what is allowed."""


class WaitTimeout(TimeoutError):
    """A wait for messages, a future or a condition ran out of time."""
