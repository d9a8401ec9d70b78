"""Nodes in child processes, reaped when the runtime stops (chapters 01, 06, 07, 08, 10).

A child-process node talks to the kernel's nodes over a real Fast DDS transport
(shared memory or UDP), and can be killed to show that ROS 2 has no master.
Children start in their own session, so the kernel's interrupt button does not
reach them; each asks Linux to end it if the kernel dies.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field

from .errors import CourseError

STOP_GRACE_S = 2.0  # s; SIGTERM, then SIGKILL after this long (a clean stop takes about 0.2 s)


@dataclass
class ChildNode:
    """A node (or nodes) running in a child Python process."""

    name: str
    target: str
    kwargs: dict
    process: subprocess.Popen
    log_path: str
    started: float = field(default_factory=time.monotonic)
    stop_requested: bool = False

    @property
    def pid(self) -> int:
        """The child's process ID."""
        return self.process.pid

    @property
    def alive(self) -> bool:
        """True while the process runs."""
        return self.process.poll() is None

    @property
    def returncode(self) -> int | None:
        """The exit code, or None while running (negative: killed by that signal)."""
        return self.process.poll()

    def kill(self) -> None:
        """Kill the process at once with SIGKILL, as a crash would (no clean shutdown)."""
        if self.alive:
            self.process.kill()
        self.process.wait(timeout=5)

    def request_stop(self) -> None:
        """Send SIGTERM and return at once (``stop()`` then waits for the exit)."""
        if self.alive and not self.stop_requested:
            self.process.send_signal(signal.SIGTERM)
            self.stop_requested = True

    def stop(self, grace_s: float = STOP_GRACE_S) -> int:
        """Ask the process to shut down (SIGTERM); SIGKILL it if it has not within ``grace_s``."""
        if self.alive:
            self.request_stop()
            try:
                self.process.wait(timeout=grace_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=5)
        return self.process.returncode

    def log(self) -> str:
        """What the child printed (stdout and stderr)."""
        try:
            with open(self.log_path, encoding="utf-8", errors="replace") as handle:
                return handle.read()
        except OSError:
            return ""

    def __repr__(self) -> str:
        state = "running" if self.alive else f"exited {self.returncode}"
        return f"<ChildNode {self.name!r} pid={self.pid} {state}>"


def start_child(name: str, target: str, kwargs: dict, extra_env: dict | None = None,
                log_dir: str | None = None) -> ChildNode:
    """Start ``target`` (``'module:callable'``) in a child process with the kernel's ROS setup."""
    if not isinstance(target, str) or ":" not in target:
        raise CourseError(
            f"target must be 'package.module:callable' (for example "
            f"'course_helpers.nodes:make_talker'), got {target!r}"
        )
    try:
        payload = json.dumps(kwargs or {})
    except TypeError as exc:
        raise CourseError(f"child-process arguments must be JSON values: {exc}") from None
    env = dict(os.environ)
    env.update({k: str(v) for k, v in (extra_env or {}).items()})
    env["COURSE_PARENT_PID"] = str(os.getpid())
    env["PYTHONUNBUFFERED"] = "1"
    env.setdefault("RCUTILS_COLORIZED_OUTPUT", "0")
    log_dir = log_dir or tempfile.gettempdir()
    log_path = os.path.join(log_dir, f"child-{name}-{os.getpid()}-{time.monotonic_ns()}.log")
    with open(log_path, "wb") as log:
        process = subprocess.Popen(
            [sys.executable, "-m", "course_helpers.child", target, payload],
            stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
            env=env, start_new_session=True, cwd=os.getcwd(),
        )
    return ChildNode(name, target, dict(kwargs or {}), process, log_path)
