"""The one verdict of the course: pass, fail, or inconclusive on a busy machine.

Every verdict a user meets (a test, a checker's criterion, a notebook's claim) is one of two kinds.

* **By construction** (:func:`judge`): what the mechanism guarantees on any machine, such as "a
  reliable reader got every sample" or "a repaired sample came after a HEARTBEAT and an ACKNACK that
  named it" (not "a heartbeat period after its first send": the next HEARTBEAT may follow the loss at
  once, notebook 08c). It passes or fails, whatever the load.
* **Timing** (:func:`judge_timing`): a measurement against a bound that a busy machine can only push
  toward failing, such as "a node in a new process is seen within 0.5 s". The measurement runs under a
  :class:`~course_helpers.core.machine_load.LoadMeter`:

  - it holds: **pass** (a loaded machine only makes such a bound harder to meet);
  - it does not hold, and the machine was quiet: **fail**, with the measured values;
  - it does not hold, and the machine was busy: measured again, at most :data:`ATTEMPTS` times in
    all; still not holding on a busy machine, it is **inconclusive**, with the load that made it so.

Python's cyclic garbage collector is kept out of every timing measurement (:func:`collector_paused`):
a full collection in a large process holds the interpreter for a tenth of a second or more (up to
1.5 s in a pytest worker that had run the timing tests), stalling every callback, and no load meter
sees it, because the process itself is running. Reference counting still frees what the
measurement drops; cycles wait until it ends.

Inconclusive is never a pass: :meth:`Verdict.raise_unless_passed` raises for it as for a failure,
with one line that says why and what to do. On a quiet machine a verdict is never inconclusive.
"""

from __future__ import annotations

import contextlib
import gc
import json
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import TypeVar

from course_helpers.core.machine_load import LoadMeter, MachineLoad

PASS, FAIL, INCONCLUSIVE = "pass", "fail", "inconclusive"
ATTEMPTS = 3  # a timing measurement that fails on a busy machine is made this often in all
MARKS = {PASS: "\u2714", FAIL: "\u2718", INCONCLUSIVE: "inconclusive (busy machine):"}

T = TypeVar("T")
TIMING_WATCHERS: list[Callable[[str], None]] = []  # told each timing statement judged (tests' stage check)
# The same for the processes a test starts (kernels, graders, children): where this variable names a
# file, each timing statement judged is appended to it as a line of JSON (tests/conftest.py sets it).
TIMING_RECORD_VARIABLE = "COURSE_TIMING_RECORD"


class VerdictError(AssertionError):
    """A verdict that did not pass. In a notebook it shows as its one line, not as a traceback; as an
    AssertionError it fails a test and an nbval cell like any assertion."""

    def __init__(self, verdict: Verdict):
        super().__init__(verdict.line())
        self.verdict = verdict

    def _render_traceback_(self) -> list[str]:  # IPython shows this instead of the traceback
        return [f"\x1b[0;31m{self}\x1b[0m"]


class TimingVerdictError(VerdictError):
    """A timing verdict that did not pass: it failed on a quiet machine or stayed inconclusive on a
    busy one. Its own name lets a reader of a notebook's errors tell it from a claim by construction
    (the release check does: tools/assignments.py)."""


@dataclass(frozen=True)
class Verdict:
    """One judged statement: what was claimed, the outcome, what was measured, and the load met."""

    statement: str
    outcome: str  # PASS, FAIL or INCONCLUSIVE
    measured: str = ""  # the measured values, in words ("p90 0.18 s")
    load: MachineLoad | None = None  # None: judged by construction, load plays no part
    attempts: int = 1
    printed: bool = field(default=False, compare=False, repr=False)  # its line is already in the output

    def _ipython_display_(self) -> None:
        """A cell that ends with a claim shows its line once: claim() printed it already."""
        if not self.printed:
            print(self.line())

    @property
    def passed(self) -> bool:
        return self.outcome == PASS

    def why(self) -> str:
        """For an inconclusive verdict, the load and what to do, in one sentence; otherwise ''."""
        if self.outcome != INCONCLUSIVE or self.load is None:
            return ""
        tries = f"{self.attempts} time{'s' if self.attempts != 1 else ''}"
        course = self.load.course_processes()
        return (f"this machine was too busy to judge it ({self.load.reading()}"
                f"{'; ' + course + ' running' if course else ''}); measured {tries}. To judge it, "
                f"{self.load.advice()}")

    def line(self) -> str:
        """'✔ statement: measured', '✘ statement: measured', or 'inconclusive (busy machine): ...'."""
        text = f"{MARKS[self.outcome]} {self.statement}"
        if self.measured:
            text += f": {self.measured}"
        if self.outcome == INCONCLUSIVE:
            text += f". {self.why()}."
        return text

    def raise_unless_passed(self) -> Verdict:
        """Return the verdict if it passed; raise :class:`VerdictError` (an AssertionError) otherwise,
        :class:`TimingVerdictError` for a timing verdict (one judged under a load meter)."""
        if not self.passed:
            raise (VerdictError if self.load is None else TimingVerdictError)(self)
        return self


def judge(statement: str, holds: object, measured: str = "") -> Verdict:
    """A verdict by construction: PASS if ``holds`` is true, FAIL otherwise (load plays no part)."""
    return Verdict(statement, PASS if holds else FAIL, measured)


def tell_timing_watchers(statement: str) -> None:
    """Tell :data:`TIMING_WATCHERS`, and the record :data:`TIMING_RECORD_VARIABLE` names, that
    ``statement`` is judged on the wall clock."""
    for watcher in list(TIMING_WATCHERS):
        watcher(statement)
    record = os.environ.get(TIMING_RECORD_VARIABLE)
    if not record:
        return
    try:
        with open(record, "a", encoding="utf-8") as out:
            out.write(json.dumps(statement) + "\n")
    except PermissionError:
        pass  # a kernel run as another user (a hub's student) cannot; tests.servers.KernelChannels tells


def judge_timing(statement: str, measure: Callable[[], T], holds: Callable[[T], object],
                 show: Callable[[T], str] = str, attempts: int = ATTEMPTS,
                 course_kernels: bool = True) -> tuple[Verdict, T]:
    """Measure, and judge the measurement against a bound that load can only push toward failing.

    Args:
        statement: the claim, in words ("a node in a new process is seen within 0.5 s, p90 of 10").
        measure: makes one measurement and returns it (it may start nodes, wait and count).
        holds: True if a measurement meets the bound.
        show: the measurement in words, for the verdict's line.
        attempts: how often, in all, a measurement that misses the bound on a busy machine is made.
        course_kernels: look for other course kernels when the machine was busy (the advice names them).

    Returns:
        ``(verdict, the last measurement)``; see the module docstring for the outcomes.
    """
    if attempts < 1:
        raise ValueError(f"attempts must be at least 1, got {attempts!r}")
    tell_timing_watchers(statement)
    for attempt in range(1, attempts + 1):
        with collector_paused():
            meter = LoadMeter()
            value = measure()
            load = meter.finish(course_kernels=course_kernels and attempt == attempts)
        if holds(value):
            return Verdict(statement, PASS, show(value), load, attempt), value
        if not load.busy:
            return Verdict(statement, FAIL, show(value), load, attempt), value
    return Verdict(statement, INCONCLUSIVE, show(value), load, attempts), value


@contextlib.contextmanager
def collector_paused() -> Iterator[None]:
    """Pause Python's cyclic garbage collector for the block (see the module docstring); it runs
    again afterwards, unless it was off before."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def reusing(first: T, measure: Callable[[], T]) -> Callable[[], T]:
    """A ``measure`` for :func:`claim_timing` that returns ``first`` (a measurement an earlier cell
    made) the first time and measures anew only for a retry."""
    pending = [first]

    def once_then_measure() -> T:
        return pending.pop() if pending else measure()

    return once_then_measure


def claim(statement: str, holds: object, measured: str = "") -> Verdict:
    """A notebook's claim that holds by construction: print its line (✔ or ✘, the statement and the
    measured values) and raise :class:`VerdictError` if it does not hold."""
    verdict = judge(statement, holds, measured)
    print(verdict.line(), flush=True)
    return replace(verdict, printed=True).raise_unless_passed()


def claim_timing(statement: str, measure: Callable[[], T], holds: Callable[[T], object],
                 show: Callable[[T], str] = str, attempts: int = ATTEMPTS) -> T:
    """A notebook's timing claim (:func:`judge_timing`): print its line and return the measurement;
    raise :class:`VerdictError` if it failed or stayed inconclusive."""
    verdict, value = judge_timing(statement, measure, holds, show, attempts)
    print(verdict.line(), flush=True)
    verdict.raise_unless_passed()
    return value
