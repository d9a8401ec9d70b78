"""Child-process targets the tests start (a child imports its target, so they live in a module)."""

from __future__ import annotations

from course_helpers.core.channel import report


def count_then_report(count: int = 3) -> None:
    """A procedure: report each step, then the total, and return (the process exits)."""
    for i in range(count):
        report("step", i=i)
    report("done", total=count)


def fail_after_report() -> None:
    """A procedure that fails: the child reports the error and exits 1."""
    raise RuntimeError("measured nothing")
