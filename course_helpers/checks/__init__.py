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


@dataclass
class Criterion:
    """One thing a checker verifies, with the hint shown when it fails."""

    name: str
    passed: bool
    detail: str = ""
    hint: str = ""


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
            line = f"  [{'pass' if c.passed else 'FAIL'}] {c.name}"
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
            colour = "#1a7f37" if c.passed else "#cf222e"
            mark = "&#10004;" if c.passed else "&#10008;"
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
