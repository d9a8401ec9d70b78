"""Chapter 02 (nodes and executors): its measurements, plots and the C++ program on rcl.

* :mod:`.blocking`: a blocking callback beside a control timer, in different executors and
  callback groups (:func:`measure_blocking`, :func:`plot_tick_gaps`, :func:`spin_for`);
* :mod:`.jitter`: how late a timer's calls start, idle and beside a CPU-heavy callback
  (:func:`measure_timer_jitter`, :func:`plot_jitter`);
* :mod:`.participant_life`: when a context's DDS participant exists, seen from outside it
  (:class:`ParticipantWatch`);
* :mod:`.rcl_programs`: compile a small C++ program on rcl and run it as a course child process
  (:func:`build_rcl_program`, :func:`run_program`).
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
from course_helpers.chapters.ch02_executors.participant_life import Footprint, ParticipantWatch
from course_helpers.chapters.ch02_executors.rcl_programs import (
    RclProgram,
    build_rcl_program,
    message_packages,
    run_program,
)

__all__ = [
    "EXECUTORS",
    "ControlLoopWithPlanner",
    "DueWhileBusy",
    "Footprint",
    "GapResult",
    "JitterProbe",
    "JitterResult",
    "ParticipantWatch",
    "RclProgram",
    "build_rcl_program",
    "measure_blocking",
    "measure_timer_jitter",
    "message_packages",
    "plot_jitter",
    "plot_tick_gaps",
    "run_program",
    "spin_for",
    "spinning_alone",
    "tick_gaps",
]
