"""The failure experiment's record and its table: what still works when the process in the middle dies.

Chapter 01 kills ROS 1's master and a ROS 2 node; chapter 07 kills a Fast DDS discovery server.
Each experiment fills in a :class:`FailureResult` from what it measured, and :func:`side_by_side`
prints several as one text table, a column per system.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from course_helpers.core.errors import CourseError

KEEP_TALKING_MESSAGES = 5  # "the pair keeps talking" = this many more messages after the kill


@dataclass
class FailureResult:
    """What one failure experiment measured (times in seconds)."""

    system: str  # 'ROS 1', 'ROS 2', ...: the column's title
    killed: str  # what was killed, and how
    first_message_s: float  # the first listener: how long it needed to hear the talker
    kept_talking: bool  # the pair exchanged KEEP_TALKING_MESSAGES more messages after the kill
    kept_talking_s: float | None  # ... within this long
    newcomer_heard: bool  # a listener started after the kill heard the talker
    newcomer_s: float | None  # ... this long after its start (None: nothing heard)
    newcomer_window_s: float  # how long the newcomer was given
    after_restart: str  # what the restarted process knew, as measured, in a few words
    known_before: list[str] | None = None  # who the centre knew before the kill (None: not asked)
    restarted_knows: list[str] | None = None  # who the restarted process knew (None: not asked)
    restart_s: float | None = None  # from the restart to what ``after_restart`` says
    notes: list[str] = field(default_factory=list)


def seconds(value: float | None) -> str:
    """``'1.23 s'``, or ``'-'`` for None."""
    return "-" if value is None else f"{value:.2f} s"


def names(found: list[str]) -> str:
    """Node names as a list for a table cell (``'nobody'`` when empty)."""
    return ", ".join(found) or "nobody"


def side_by_side(*results: FailureResult) -> str:
    """A text table of failure experiments, one column per result, every cell from what it measured.

    The row "known before the kill" appears when every result asked it.
    """
    if not results or not all(isinstance(r, FailureResult) for r in results):
        raise CourseError(f"side_by_side() takes one or more FailureResult, got {results!r}")
    rows = [("killed", [r.killed for r in results]),
            ("first message at start", [seconds(r.first_message_s) for r in results])]
    if all(r.known_before is not None for r in results):
        rows.append(("known before the kill", [names(r.known_before) for r in results]))
    rows += [
        ("the pair kept talking", [f"yes, {KEEP_TALKING_MESSAGES} messages in {seconds(r.kept_talking_s)}"
                                   if r.kept_talking else "no" for r in results]),
        ("a new listener heard the talker", [f"yes, after {seconds(r.newcomer_s)}" if r.newcomer_heard
                                             else f"no, nothing in {seconds(r.newcomer_window_s)}"
                                             for r in results]),
        ("after the restart", [r.after_restart for r in results]),
    ]
    width = max(len(label) for label, _ in rows) + 2
    columns = [max(len(r.system), *(len(values[i]) for _, values in rows)) + 2 for i, r in enumerate(results)]
    lines = [" " * width + "".join(r.system.ljust(columns[i]) for i, r in enumerate(results))]
    for label, values in rows:
        lines.append(label.ljust(width) + "".join(v.ljust(columns[i]) for i, v in enumerate(values)))
    return "\n".join(line.rstrip() for line in lines)
