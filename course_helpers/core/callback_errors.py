"""A node callback's exception, told so that a student can act on it.

rclpy calls a callback from deep inside its executor, so a full traceback is mostly rclpy's own
frames, and a callback that fails on every message prints the same block ten times a second. This
module keeps what the student wrote: the error, then the frames of their own code (a cell's line,
or their file's), and it counts repeats instead of printing them again.
"""

from __future__ import annotations

import os
import re
import threading
import traceback

import rclpy

# Frames nobody in the course wrote or can change: rclpy's executor and the runtime that calls it.
_MACHINERY = (
    os.path.dirname(os.path.abspath(rclpy.__file__)) + os.sep,
    os.path.dirname(os.path.abspath(__file__)) + os.sep,
    os.path.dirname(os.path.abspath(threading.__file__)) + os.sep + "threading.py",
)
_CELL_FILE = re.compile(r"[/\\]ipykernel_\d+[/\\]\d+\.py$")

def _is_machinery(filename: str) -> bool:
    path = os.path.abspath(filename)
    return any(path.startswith(prefix) for prefix in _MACHINERY)


def _place(frame: traceback.FrameSummary) -> str:
    where = "a cell" if _CELL_FILE.search(frame.filename) else frame.filename
    code = f": {frame.line.strip()}" if frame.line else ""
    return f"  at {frame.name} ({where}, line {frame.lineno}){code}"


def _own_frames(exc: BaseException) -> list[traceback.FrameSummary]:
    """The frames of the student's code; the innermost frame when every frame is machinery."""
    frames = traceback.extract_tb(exc.__traceback__)
    own = [frame for frame in frames if not _is_machinery(frame.filename)]
    return own or frames[-1:]


def _headline(exc: BaseException) -> str:
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def describe(exc: BaseException) -> str:
    """The error's line, then one line per frame of the student's code, then any cause."""
    lines = [_headline(exc)] + [_place(frame) for frame in _own_frames(exc)]
    cause = exc.__cause__ or (None if exc.__suppress_context__ else exc.__context__)
    if cause is not None:
        lines.append(f"  raised while handling {_headline(cause)}")
    return "\n".join(lines)


def _signature(where: str, exc: BaseException) -> tuple:
    frames = traceback.extract_tb(exc.__traceback__)
    last = (frames[-1].filename, frames[-1].lineno) if frames else None
    return where, type(exc).__name__, last


class RepeatCounter:
    """Counts each distinct error of each callback owner, and says when a repeat is worth a line."""

    def __init__(self):
        self._counts: dict[tuple, int] = {}
        self._lock = threading.Lock()

    def report(self, where: str, exc: BaseException) -> str | None:
        """The text to show for this error, or None while it only repeats."""
        key = _signature(where, exc)
        with self._lock:
            count = self._counts.get(key, 0) + 1
            self._counts[key] = count
        if count == 1:
            return f"[callback error in {where}] {describe(exc)}\n"
        if _is_power_of_ten(count):  # 10, 100, 1000 ...: the console says it goes on, not each time
            return (f"[callback error in {where}] the same {type(exc).__name__} again: "
                    f"{count} times so far\n")
        return None


def _is_power_of_ten(count: int) -> bool:
    while count >= 10 and count % 10 == 0:
        count //= 10
    return count == 1
