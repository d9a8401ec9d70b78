"""The one timing verdict for tests: a measured bound is asserted with ``assert_timing``, never with a bare
assert. On a busy machine a missed bound is measured again (core/verdict.py), and one still missed
fails as inconclusive, naming the load; on a quiet machine it fails at once, with the measurement."""

from __future__ import annotations

from course_helpers.core.verdict import judge_timing


def assert_timing(statement: str, measure, holds, show=repr):
    """Measure, judge with the timing verdict, and return the measurement; raise (an AssertionError)
    unless it passed. ``measure`` must measure anew each time it is called."""
    verdict, value = judge_timing(statement, measure, holds, show=show, course_kernels=False)
    verdict.raise_unless_passed()
    return value
