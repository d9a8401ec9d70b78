"""A child's process group, seen from the kernel: signalled whole, its leader's exit awaited safely.

Every course child is the leader of a session and process group of its own, so its PID is also
the group's ID. :class:`ProcessGroup` signals the whole group, waits for the leader's exit on a
pidfd (an event: no polling) and reads it with ``waitid(WNOWAIT)``, without reaping. The leader
is reaped only in :meth:`ProcessGroup.finish`, after what is left of its group has been killed:
until then its PID cannot be given to a new process, so a signal to the group never reaches an
unrelated one that happened to get the same number.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess

from course_helpers.core.waiting import poll_until


class ProcessGroup:
    """The process group led by ``process`` (started with ``start_new_session=True``)."""

    def __init__(self, process: subprocess.Popen):
        self.process = process
        try:
            self._pidfd: int | None = os.pidfd_open(process.pid)
        except (AttributeError, OSError):  # Linux before 5.3: exits are polled instead
            self._pidfd = None

    def code(self) -> int | None:
        """The exit code (negative: the signal that ended it), or None while it runs."""
        if self.process.returncode is not None:
            return self.process.returncode
        try:
            info = os.waitid(os.P_PID, self.process.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
        except ChildProcessError:  # reaped by someone else: let Popen say how it ended
            return self.process.poll()
        if info is None:
            return None
        return info.si_status if info.si_code == os.CLD_EXITED else -info.si_status

    def wait(self, timeout: float) -> bool:
        """Wait up to ``timeout`` seconds for the exit (without reaping); True if it has exited."""
        if self.code() is not None:
            return True
        if self._pidfd is None:
            return poll_until(lambda: self.code() is not None, timeout)
        poller = select.poll()
        poller.register(self._pidfd, select.POLLIN)
        poller.poll(None if timeout == float("inf") else max(0, int(timeout * 1000) + 1))
        return self.code() is not None

    def signal_group(self, sig: int) -> None:
        """Send ``sig`` to the whole process group (nothing once the child has been reaped)."""
        if self.process.returncode is not None:
            return
        try:
            os.killpg(self.process.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass

    def finish(self) -> None:
        """Once the child has exited: kill what is left of its group, then reap the child."""
        if self.process.returncode is not None or self.code() is None:
            return
        self.signal_group(signal.SIGKILL)
        self.process.wait()
        if self._pidfd is not None:
            os.close(self._pidfd)
            self._pidfd = None
