"""Chapter 02 (nodes and executors): its measurements and plots.

* :mod:`.blocking`: a blocking callback beside a control timer, in different executors and
  callback groups (:func:`measure_blocking`, :func:`plot_tick_gaps`, :func:`spin_for`);
* :mod:`.jitter`: how late a timer's calls start, idle and beside a CPU-heavy callback
  (:func:`measure_timer_jitter`, :func:`plot_jitter`).
"""

from course_helpers.chapters.ch02_executors.blocking import (
    EXECUTORS,
    ControlLoopWithPlanner,
    GapResult,
    measure_blocking,
    plot_tick_gaps,
    spin_for,
    spinning_alone,
    tick_gaps,
)
from course_helpers.chapters.ch02_executors.jitter import (
    DueWhileBusy,
    JitterProbe,
    JitterResult,
    measure_timer_jitter,
    plot_jitter,
)

__all__ = [
    "EXECUTORS",
    "ControlLoopWithPlanner",
    "DueWhileBusy",
    "GapResult",
    "JitterProbe",
    "JitterResult",
    "measure_blocking",
    "measure_timer_jitter",
    "plot_jitter",
    "plot_tick_gaps",
    "spin_for",
    "spinning_alone",
    "tick_gaps",
]
