"""A live indicator for a build that takes a while: ``ws.build(progress=build_progress())``.

In a notebook the indicator is the course's progress bar
(:class:`~course_helpers.notebook.progress.ProgressWithRecord`) with the elapsed time and the latest
line, and under it a static record: when the build ends, the record lists the build's steps with
the time each took and the result, so a saved copy of the notebook shows what happened.
"""

from __future__ import annotations

import html
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from course_helpers.core.console import in_jupyter_kernel

# An absolute path (two parts or more) in a build line: shown by its last part only.
_PATH = re.compile(r"(?<![\w.])/(?:[^\s/()]+/)+([^\s/()]+)")
_END_LINES = ("done", "FAILED")
MAX_STEPS = 12  # steps kept in the record (the first and the latest ones)


def short_line(line: str, width: int = 90) -> str:
    """A build line for people: absolute paths shortened to ``.../last_part``, at most ``width``
    characters."""
    shown = _PATH.sub(r".../\1", line.strip())
    return shown if len(shown) <= width else shown[: width - 3] + "..."


@dataclass
class BuildSteps:
    """The lines a build reported, each with the time since the start [s], and how it ended."""

    title: str
    started: float = field(default_factory=time.monotonic)
    steps: list[tuple[float, str]] = field(default_factory=list)
    result: str | None = None  # 'done' or 'FAILED' once the build ended
    seconds: float | None = None

    def add(self, line: str) -> None:
        """Note one line the build printed ('done' or 'FAILED' ends it)."""
        now = time.monotonic() - self.started
        if line in _END_LINES:
            self.result, self.seconds = line, now
        elif line.strip():
            self.steps.append((now, short_line(line)))

    def rows(self) -> list[tuple[str, str]]:
        """(step, how long it took) for each kept step; a step lasts until the next one."""
        if not self.steps:
            return []
        ends = [t for t, _ in self.steps[1:]] + [self.seconds]
        rows = [(text, "" if end is None else f"{end - start:.1f} s")
                for (start, text), end in zip(self.steps, ends, strict=True)]
        if len(rows) > MAX_STEPS:
            left_out = (f"... {len(rows) - MAX_STEPS} more lines ...", "")
            rows = [*rows[:2], left_out, *rows[-(MAX_STEPS - 2):]]
        return rows

    def headline(self) -> str:
        """'colcon build: succeeded in 3.2 s' (or 'FAILED after', or 'running')."""
        if self.result is None:
            return f"{self.title}: running"
        verdict = "succeeded in" if self.result == "done" else "FAILED after"
        return f"{self.title}: {verdict} {self.seconds:.1f} s"

    def text(self) -> str:
        """The record as plain text: the headline, then one line per step."""
        lines = [self.headline()]
        lines += [f"  {took:>7}  {step}" for step, took in self.rows()]
        return "\n".join(lines)

    def html(self) -> str:
        """The record as an HTML table."""
        rows = "".join(f"<tr><td><code>{html.escape(step)}</code></td><td>{took}</td></tr>"
                       for step, took in self.rows())
        colour = {"done": "#2e7d32", "FAILED": "#c62828"}.get(self.result or "", "#555")
        return (f"<p style='color:{colour}'><b>{html.escape(self.headline())}</b></p>"
                f"<table><tr><th>step</th><th>took</th></tr>{rows}</table>")


def build_progress(title: str = "colcon build") -> Callable[[str], None] | None:
    """A ``progress=`` callback for ``Workspace.build`` and ``build_interface_package``.

    Args:
        title: what the indicator calls the build.

    Returns:
        In a notebook: a function that takes each line the build prints (and 'done' or
        'FAILED' at the end) and shows a small widget with a bar, the elapsed time and the
        latest line, with a static record of the steps that is filled in when the build
        ends. Elsewhere: None (no output).
    """
    if not in_jupyter_kernel():
        return None
    from course_helpers.notebook.progress import ProgressWithRecord

    bar = ProgressWithRecord(title, label=f"{title}: starting", width="260px", style="info")
    steps = BuildSteps(title)
    bar.show(steps.text(), steps.html())

    def update(line: str) -> None:
        steps.add(line)
        elapsed = time.monotonic() - steps.started
        label = f"{title} ({elapsed:.0f} s): {short_line(line)}"
        if line in _END_LINES:
            bar.end("success" if line == "done" else "danger", label, full=True)
            bar.update_record(steps.text(), steps.html())
        else:
            bar.move(min(0.95, elapsed / (elapsed + 5.0)), label)  # creeps towards the end, never claims done

    return update
