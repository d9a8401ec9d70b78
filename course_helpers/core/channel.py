"""The one structured channel from a child process to the kernel: JSON lines with a tag.

A child reports what it measured or that it is ready with ``report('ready', nodes=[...])``.
Each report is one line ``{"tag": ..., "data": {...}, "t": <monotonic s>}`` written to a
pipe that the process layer opened for it (its descriptor is in ``COURSE_CHANNEL_FD``).
The kernel reads the pipe in a thread of its own (:class:`ChannelReader`) and keeps the
reports by tag, so nothing is ever parsed out of a log. Outside a child (a node that reports
was added in the kernel itself), ``report`` does nothing; ``python -m course_helpers.core.child``
started by hand, with no pipe, prints its reports on stdout so they can still be read.
"""

from __future__ import annotations

import json
import os
import sys
import threading
import time

from course_helpers.core.waiting import changes

CHANNEL_ENV = "COURSE_CHANNEL_FD"

_write_lock = threading.Lock()


def report(tag: str, **data) -> None:
    """Send one report to the kernel (JSON values only); safe from any thread of the child."""
    line = json.dumps({"tag": tag, "data": data, "t": time.monotonic()}) + "\n"
    fd = os.environ.get(CHANNEL_ENV)
    if fd is None and os.environ.get("COURSE_CHILD") != "1":
        return  # not a course child: nobody listens
    with _write_lock:
        if fd is None:
            sys.stdout.write(line)
            sys.stdout.flush()
            return
        payload = line.encode()
        while payload:
            written = os.write(int(fd), payload)
            payload = payload[written:]


class ChannelReader:
    """The kernel's end of a child's channel: reads its reports as they arrive, keeps them by tag."""

    def __init__(self, read_fd: int, name: str):
        self._file = os.fdopen(read_fd, "rb", buffering=0)
        self._reports: list[dict] = []
        self._lock = threading.Lock()
        self.closed = threading.Event()  # set when the child closed its end (it exited)
        self._thread = threading.Thread(target=self._read, name=f"channel-{name}", daemon=True)
        self._thread.start()

    def _read(self) -> None:
        pending = b""
        try:
            while chunk := self._file.read(65536):
                lines = (pending + chunk).split(b"\n")
                pending = lines.pop()
                for line in lines:
                    self._keep(line)
        except (OSError, ValueError):
            pass  # closed from our side at stop
        finally:
            self.closed.set()
            changes.notify()  # the child has ended: a wait for its report can stop
            try:
                self._file.close()
            except OSError:
                pass

    def _keep(self, line: bytes) -> None:
        try:
            entry = json.loads(line)
        except ValueError:
            return  # not a report (cannot happen for reports written with report())
        if isinstance(entry, dict) and "tag" in entry:
            with self._lock:
                self._reports.append(entry)
            changes.notify()

    def reports(self, tag: str | None = None) -> list[dict]:
        """The data of every report so far (of ``tag`` only, if given), oldest first."""
        with self._lock:
            return [r["data"] for r in self._reports if tag is None or r["tag"] == tag]

    def last(self, tag: str) -> dict | None:
        """The data of the newest report with ``tag``, or None."""
        with self._lock:
            for entry in reversed(self._reports):
                if entry["tag"] == tag:
                    return entry["data"]
        return None

    def count(self, tag: str) -> int:
        """How many reports with ``tag`` arrived."""
        with self._lock:
            return sum(1 for r in self._reports if r["tag"] == tag)

    def stamped(self, tag: str) -> list[tuple[float, dict]]:
        """``(child's monotonic time, data)`` of each report with ``tag`` (one clock per machine)."""
        with self._lock:
            return [(r["t"], r["data"]) for r in self._reports if r["tag"] == tag]

    def close(self, timeout: float = 2.0) -> None:
        """Wait for the reader to reach the end (the child has exited)."""
        self._thread.join(timeout)
