"""Exercise checkers: run a student's code against real nodes and report each criterion.

Every chapter's exercises end with ``check_...(student_code)``. A checker starts
real nodes with scripted inputs, watches what the student's node does, and
returns a :class:`CheckReport`: one line per criterion, passed or failed, with a
hint for each failure. Chapter modules live beside this file
(``checks/topics.py`` for chapter 03, ...); reference solutions live in
``course_helpers/solutions/`` so instructors' CI proves that every checker
accepts a correct solution and rejects a wrong one.
"""

from __future__ import annotations

import contextlib
import html
from collections.abc import Callable
from dataclasses import dataclass, field

from rclpy.node import Node

from course_helpers.core.node_hook import destroy_fully
from course_helpers.core.sim_clock import MATCH_TIMEOUT_S, SimClock
from course_helpers.core.waiting import poll_until


@dataclass
class Criterion:
    """One thing a checker verifies, with the hint shown when it fails. ``inconclusive``: a timing
    criterion missed on a busy machine, even after its retries (never a pass; the hint says why)."""

    name: str
    passed: bool
    detail: str = ""
    hint: str = ""
    inconclusive: bool = False

    @property
    def tag(self) -> str:
        return "pass" if self.passed else ("BUSY" if self.inconclusive else "FAIL")


@dataclass
class CheckReport:
    """The result of a checker: ``passed`` only when every criterion passed."""

    exercise: str
    criteria: list[Criterion] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return bool(self.criteria) and all(c.passed for c in self.criteria)

    def add(self, name: str, passed: bool, detail: str = "", hint: str = "") -> bool:
        """Record a criterion; returns ``passed`` so checkers can stop early."""
        self.criteria.append(Criterion(name, bool(passed), detail, hint))
        return bool(passed)

    def add_timed(self, results: list[tuple[str, bool, str, str]], verdict) -> bool:
        """Add the criteria of a timed scenario (see :func:`judge_timed_scenario`): as measured, except
        that a failed one is inconclusive when ``verdict`` is (its hint then says why, in one line)."""
        from course_helpers.core.verdict import INCONCLUSIVE

        for name, passed, detail, hint, *structural in results:
            if passed or verdict.outcome != INCONCLUSIVE or structural == [True]:
                self.add(name, passed, detail, hint)
            else:
                self.criteria.append(Criterion(name, False, detail, f"inconclusive: {verdict.why()}.", True))
        return all(result[1] for result in results)

    def run(self, name: str, step: Callable[[], object], hint: str = "") -> object | None:
        """Run ``step``; an exception becomes a failed criterion with the error as detail."""
        try:
            return step()
        except Exception as exc:  # the student's code raised: report it, do not crash
            self.add(name, False, _describe(exc), hint)
            return None

    def summary(self) -> str:
        """Plain text, one line per criterion (what nbval compares)."""
        verdict = "PASSED" if self.passed else "NOT YET"
        lines = [f"{self.exercise}: {verdict} {self._count()}"]
        hints = self._hints()
        for c in self.criteria:
            line = f"  [{c.tag}] {c.name}"
            if c.detail:
                line += f" - {c.detail}"
            lines.append(line)
            if hints.get(id(c)):
                lines.append(f"         hint: {c.hint}")
        return "\n".join(lines)

    def _count(self) -> str:
        return f"({sum(c.passed for c in self.criteria)}/{len(self.criteria)} criteria)"

    def _hints(self) -> dict[int, bool]:
        """Which criteria show their hint: a failed one whose hint no failed criterion before it showed
        (several cases of one exercise often fail for one reason: its hint is said once)."""
        shown, said = {}, set()
        for c in self.criteria:
            if not c.passed and c.hint and c.hint not in said:
                said.add(c.hint)
                shown[id(c)] = True
        return shown

    def __str__(self) -> str:
        return self.summary()

    def _repr_html_(self) -> str:
        rows, hints = [], self._hints()
        for c in self.criteria:
            colour = "#1a7f37" if c.passed else ("#9a6700" if c.inconclusive else "#cf222e")
            mark = "&#10004;" if c.passed else ("?" if c.inconclusive else "&#10008;")
            hint = f"<br><small>Hint: {html.escape(c.hint)}</small>" if hints.get(id(c)) else ""
            detail = f" <small>({html.escape(c.detail)})</small>" if c.detail else ""
            rows.append(f"<li style='color:{colour}'>{mark} {html.escape(c.name)}{detail}{hint}</li>")
        verdict = "passed" if self.passed else "not passed yet"
        return (f"<div><b>{html.escape(self.exercise)}: {verdict} {self._count()}</b>"
                f"<ul style='list-style:none'>{''.join(rows)}</ul></div>")

    def _repr_pretty_(self, printer, cycle):
        printer.text(self.summary())


def _describe(exc: BaseException) -> str:
    """``ValueError: message``: the error's class and message, without notes or module path."""
    message = str(exc).strip()
    return f"{type(exc).__name__}: {message}" if message else type(exc).__name__


@contextlib.contextmanager
def student_node(report: CheckReport, rt, node_class, probe_name: str):
    """Run the student's node and a probe node beside it; remove both afterwards.

    Yields ``(node, probe)``, or ``(None, None)`` when the student's class could not be built
    (the report then holds that failure). ``node_class`` is built without arguments.
    """
    node = report.run("the node can be created", lambda: rt.add(node_class, console=False),
                      hint="Run the class cell first; the constructor must take no arguments.")
    if node is None:
        yield None, None
        return
    probe = rt.add(Node, probe_name, console=False)
    try:
        yield node, probe
    finally:
        rt.remove(probe)  # the runtime also destroys the action servers and clients a node leaves behind
        rt.remove(node)


@contextlib.contextmanager
def student_on_clock(report: CheckReport, rt, node_class, probe_name: str, *,
                     created: str = "the node can be created",
                     hint: str = "Run the class cell first; the constructor must take no arguments.",
                     **build_kwargs):
    """Run the student's node on a clock the checker owns, with a probe node beside it.

    Both are built in ``rt``'s context but spun only by a :class:`~course_helpers.core.sim_clock.SimClock`
    (``use_sim_time`` on): time moves when the checker says, and after each step every message has
    arrived and every callback has run. The verdict is the same on any machine, however busy, and a
    scenario of many seconds takes a fraction of one. The class is built with ``build_kwargs``; if
    that fails, the criterion ``created`` fails with ``hint``. Yields ``(node, probe, clock)``, or
    ``(None, None, None)`` when the student's class could not be built (the report holds that
    failure). The student's callback errors are in ``clock.errors``.
    """
    clock = SimClock(rt)
    node = report.run(created, lambda: rt.build(node_class, **build_kwargs), hint=hint)
    try:
        if node is None:
            yield None, None, None
            return
        clock.drive(node)
        probe = clock.drive(rt.build(Node, probe_name, enable_rosout=False, start_parameter_services=False))
        yield node, probe, clock
    finally:
        driven = list(clock.driven)
        clock.close()
        for built in driven:
            with contextlib.suppress(Exception):  # the student's destroy_node may have run already
                destroy_fully(built)


def callback_errors_criterion(report: CheckReport, errors: list[BaseException]) -> bool:
    """The criterion "callbacks raised no errors", from the errors a SimClock kept."""
    first = f"{type(errors[0]).__name__}: {errors[0]}" if errors else ""
    return report.add("callbacks raised no errors", not errors, first.splitlines()[0] if first else "",
                      hint="Run your node in a cell of its own and read the traceback in its console.")


def client_reaches(client, service) -> tuple[bool, str]:
    """Whether ``client`` can reach ``service`` (both of this process): (True, '') once they have
    matched, or (False, why) at once when their QoS profiles cannot match (a client's requests and a
    server's replies each need a compatible pair; rclpy's own compatibility check decides).
    A compatible pair matches a moment after both exist; the wait only bounds a hang."""
    from rclpy.qos import QoSCompatibility, qos_check_compatible

    for writer, reader, what in ((client.qos_profile, service.qos_profile, "requests"),
                                 (service.qos_profile, client.qos_profile, "replies")):
        compatible, reason = qos_check_compatible(writer, reader)
        if compatible == QoSCompatibility.ERROR:
            return False, f"the {what} cannot flow: {reason}"
    return poll_until(client.service_is_ready, MATCH_TIMEOUT_S), ""


def judge_timed_scenario(report: CheckReport, statement: str, scenario) -> bool:
    """Run ``scenario()`` (it returns a list of ``(name, passed, detail, hint)``) whose criteria DDS or
    the operating system times on the wall clock, and add them with the one timing verdict
    (:func:`course_helpers.core.verdict.judge_timing`): on a busy machine a missed criterion is
    measured again, and one still missed is reported as inconclusive with the load, never as a pass.
    A criterion that the code's structure already decides (a fifth element True: "these callbacks
    share a mutually exclusive group, so they can never overlap") fails at once, whatever the load.
    The scenario must set up its own state each time it runs. A scenario met only on a later attempt
    says so in its first criterion's detail, with what the first attempt missed. Returns True if
    every criterion passed.
    """
    from course_helpers.core.verdict import judge_timing

    def missed(results) -> str:
        names = [result[0] for result in results if not result[1]]
        return "missed: " + "; ".join(names) if names else "every criterion met"

    def timing_met(results) -> bool:  # what load can change; structural failures need no retry
        return all(result[1] or result[4:] == (True,) for result in results)

    attempts: list[list[tuple]] = []

    def attempt() -> list[tuple]:
        attempts.append(scenario())
        return attempts[-1]

    verdict, results = judge_timing(statement, attempt, timing_met, show=missed)
    if verdict.passed and len(attempts) > 1 and results:  # say what the busy machine cost, on the first line
        name, passed, detail, *rest = results[0]
        first_miss = "; ".join(f"{r[0]} ({r[2]})" if r[2] else r[0] for r in attempts[0] if not r[1])
        note = f"met on attempt {len(attempts)} on a busy machine; attempt 1 missed: {first_miss}"
        results = [(name, passed, f"{detail}; {note}" if detail else note, *rest), *results[1:]]
    return report.add_timed(results, verdict)
