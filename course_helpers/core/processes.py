"""The one process layer: every child process of the course starts, reports and stops here.

Child-process nodes (``rt.spawn``), the nodes of packages built with colcon (chapter 09),
eProsima's discovery server (chapter 07) and launch groups (chapter 06) all go through
:func:`start`. The layer owns

* start: a labelled process; starting a label that runs already stops the old process
  first, so re-running a cell never leaves two;
* die with the parent: the child asks Linux to send it SIGTERM when the kernel dies, and
  exits at once if the kernel is already gone. Processes are forked from one long-lived
  launcher thread, because Linux ties that signal to the thread that forked the child. What
  a child started goes too (:mod:`.supervisor`);
* the channel: each child gets a pipe for structured reports (:mod:`.channel`);
* stop together: SIGTERM to all, then wait, then SIGKILL after a grace period;
* the registry of what runs, and reaping everything at exit.

Children start in their own session, so the notebook's interrupt button never reaches
them; their output (stdout and stderr) goes to a log file. Every signal goes to the child's
whole process group (stop, kill, a timeout, the reaping at exit), so a program's own children
(compilers under a build step, nodes under a shell) stop with it (:mod:`.process_groups`).
"""

from __future__ import annotations

import atexit
import codecs
import json
import os
import queue
import selectors
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future

from course_helpers.core import port_slots, scratch_dirs
from course_helpers.core.channel import CHANNEL_ENV, ChannelReader
from course_helpers.core.dds_config import environment_snapshot
from course_helpers.core.errors import CourseError
from course_helpers.core.process_groups import ProcessGroup
from course_helpers.core.supervisor import PARENT_ENV
from course_helpers.core.waiting import UNNOTIFIED_PERIOD_S, poll_until

STOP_GRACE_S = 5.0  # s; SIGTERM, then SIGKILL after this long (a clean stop takes about 0.4 s, and
# seconds on a loaded machine: a process killed before its goodbye stays in the graph for its lease)
KILL_WAIT_S = 5.0  # s; how long a SIGKILLed process may take to be gone
DRAIN_S = 1.0  # s; after a timeout, how long `run` still reads output (a process that left the group
# may hold the pipe open for ever)
OUTPUT_TAIL_CHARS = 2000
CHANNEL_PERIOD_S = 1.0  # s; a wait for a report still looks this often (the channel's events wake it)

_lock = threading.RLock()
_registry: dict[tuple[str, str], ChildProcess] = {}
_log_dir: list[str] = []


class ChildProcess:
    """A process started by the course: its label, output, reports and exit."""

    def __init__(self, label: str, group: str, argv: list[str], process: subprocess.Popen,
                 log_path: str, channel: ChannelReader | None, target: str = "",
                 stop_signal: int = signal.SIGTERM):
        self.label = label
        self.stop_signal = stop_signal
        self.group = group
        self.argv = argv
        self.process = process
        self.log_path = log_path
        self.channel = channel
        self.target = target
        self.started = time.monotonic()
        self.stop_requested = False
        self._exit = ProcessGroup(process)
        self._program_pid: int | None = None  # a program child's program, once found (see pid)

    # ------------------------------------------------------------------ state
    @property
    def name(self) -> str:
        """The label it was started with (``rt.spawn('talker', ...)`` -> 'talker')."""
        return self.label

    @property
    def pid(self) -> int:
        """The PID of the process that runs the target or the program.

        A program child (:func:`program_argv`) is a small supervisor whose only child is the
        program: this is the program's PID once the supervisor has forked it (the supervisor's
        own for the few milliseconds before). :attr:`leader_pid` is the process group's leader.
        """
        if self._program_pid is None and self.argv[1:4] == PROGRAM_ARGV[1:4] and self.alive:
            import psutil

            try:
                children = psutil.Process(self.process.pid).children()
            except psutil.Error:
                children = []
            if children:
                self._program_pid = children[0].pid
        return self._program_pid or self.process.pid

    @property
    def leader_pid(self) -> int:
        """The PID of the child the kernel started: its process group's leader (what stop signals)."""
        return self.process.pid

    @property
    def alive(self) -> bool:
        """True while the process runs."""
        return self._exit.code() is None

    @property
    def returncode(self) -> int | None:
        """The exit code, or None while running (negative: ended by that signal)."""
        return self._exit.code()

    # ------------------------------------------------------------------ output and reports
    def log(self) -> str:
        """Everything the process printed (stdout and stderr)."""
        try:
            with open(self.log_path, encoding="utf-8", errors="replace") as handle:
                return handle.read()
        except OSError:
            return ""

    def output_tail(self, chars: int = OUTPUT_TAIL_CHARS) -> str:
        """The end of :meth:`log`, for error messages."""
        return self.log()[-chars:]

    def reports(self, tag: str | None = None) -> list[dict]:
        """The reports the child sent over its channel (of ``tag`` only, if given)."""
        return self.channel.reports(tag) if self.channel is not None else []

    def last(self, tag: str) -> dict | None:
        """The newest report with ``tag``, or None."""
        return self.channel.last(tag) if self.channel is not None else None

    def failure(self, what: str) -> CourseError:
        """An error saying the process ended while ``what`` was awaited, with its output."""
        return CourseError(f"{self.group} process {self.label!r} exited with code {self.returncode} "
                           f"before {what}. Its output:\n{self.output_tail()}")

    def wait_for_report(self, tag: str, timeout: float, what: str | None = None) -> dict:
        """Wait for a report with ``tag``; raise if the process ends or ``timeout`` passes first."""
        from course_helpers.core.errors import WaitTimeout

        what = what or f"its {tag!r} report"
        # a report, and the end of a child with a channel, wake the wait; a child without one is
        # looked at every UNNOTIFIED_PERIOD_S
        period = CHANNEL_PERIOD_S if self.channel is not None else UNNOTIFIED_PERIOD_S
        poll_until(lambda: self.last(tag) is not None or not self.alive, timeout, period)
        found = self.last(tag)
        if found is None and self.channel is not None and not self.alive:
            self.channel.close()  # the pipe may still hold the last reports
            found = self.last(tag)
        if found is not None:
            return found
        if not self.alive:
            raise self.failure(what)
        raise WaitTimeout(f"timed out after {timeout:g} s waiting for {what} from {self.group} "
                          f"process {self.label!r}. Its output:\n{self.output_tail()}")

    def wait_for_exit(self, timeout: float, what: str | None = None) -> int:
        """Wait until the process exits on its own; its exit code. Raises WaitTimeout."""
        from course_helpers.core.errors import WaitTimeout

        if not self._exit.wait(timeout):
            raise WaitTimeout(f"timed out after {timeout:g} s waiting for {what or 'it to finish'} "
                              f"({self.group} process {self.label!r})")
        self._exit.finish()
        if self.channel is not None:
            self.channel.close()
        return self.returncode

    # ------------------------------------------------------------------ stopping
    def kill(self) -> None:
        """Kill the process and its whole group at once with SIGKILL, as a crash would."""
        self._exit.signal_group(signal.SIGKILL)
        self._exit.wait(KILL_WAIT_S)
        self._exit.finish()

    def request_stop(self) -> None:
        """Send the stop signal to the process group and return at once (:meth:`stop` then waits)."""
        if self.alive and not self.stop_requested:
            self._exit.signal_group(self.stop_signal)
            self.stop_requested = True

    def stop(self, grace_s: float = STOP_GRACE_S) -> int:
        """Ask the process group to end (SIGTERM, or SIGINT for a ``ros2 run``-style program); SIGKILL
        it if the process has not ended within ``grace_s``. What is left of the group is killed."""
        if self.alive:
            self.request_stop()
            if not self._exit.wait(grace_s):
                self._exit.signal_group(signal.SIGKILL)
                self._exit.wait(KILL_WAIT_S)
        self._exit.finish()
        if self.channel is not None:
            self.channel.close()
        with _lock:
            if _registry.get((self.group, self.label)) is self:
                del _registry[(self.group, self.label)]
        return self.returncode

    def __repr__(self) -> str:
        state = "running" if self.alive else f"exited {self.returncode}"
        return f"<ChildProcess {self.label!r} pid={self.pid} {state}>"


# ---------------------------------------------------------------------- commands
def target_spec(target) -> str:
    """``'module:callable'`` for a child-process target given as a string or as the function.

    A function must be defined at the top level of an importable module, so that the child
    can import it; passing the function itself makes a moved or renamed target fail where it
    is imported, not later in the child.
    """
    if isinstance(target, str):
        module, _, attr = target.partition(":")
        if module and attr and all(part.isidentifier() for part in (*module.split("."), *attr.split("."))):
            return target
        raise CourseError(f"target must be 'package.module:callable' (for example "
                          f"'course_helpers.nodes.chatter:make_talker') or the function itself, "
                          f"got {target!r}")
    if callable(target):
        module = getattr(target, "__module__", None)
        qualname = getattr(target, "__qualname__", "")
        if not module or module == "__main__" or "<" in qualname:
            raise CourseError(
                f"{qualname or target!r} cannot run in a child process: a child imports its target, "
                "so it must be a function or class defined at the top level of a module (not in a "
                "notebook cell, not a lambda or a nested function). Put it in a .py file next to "
                "the notebook and import it from there.")
        return f"{module}:{qualname}"
    raise CourseError(f"target must be a function, a Node subclass or 'module:callable', "
                      f"got {type(target).__name__}")


def python_target_argv(target, kwargs: dict | None = None) -> list[str]:
    """The command line that runs ``target(**kwargs)`` in a child (see :mod:`.child`)."""
    spec = target_spec(target)
    try:
        payload = json.dumps(kwargs or {})
    except TypeError as exc:
        raise CourseError(f"child-process arguments must be JSON values (numbers, strings, lists, "
                          f"dicts): {exc}") from None
    return [sys.executable, "-m", "course_helpers.core.child", "run", spec, payload]


PROGRAM_ARGV = [sys.executable, "-m", "course_helpers.core.child", "exec"]


def program_argv(program: str, *args: str) -> list[str]:
    """The command line that runs an executable so that it dies with the kernel."""
    return [*PROGRAM_ARGV, program, *map(str, args)]


# ---------------------------------------------------------------------- starting
class _Launcher:
    """One long-lived thread that forks every child (PR_SET_PDEATHSIG follows the forking thread)."""

    def __init__(self):
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._guard = threading.Lock()

    def run(self, job: Callable[[], object]):
        with self._guard:
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(target=self._serve, name="course-launcher", daemon=True)
                self._thread.start()
        future: Future = Future()
        self._jobs.put((job, future))
        return future.result()

    def _serve(self) -> None:
        while True:
            job, future = self._jobs.get()
            try:
                future.set_result(job())
            except BaseException as exc:  # handed to the caller
                future.set_exception(exc)


_launcher = _Launcher()


def log_dir() -> str:
    """This process's folder for child logs (removed at exit; swept by the next one if killed)."""
    with _lock:
        if not _log_dir:
            _log_dir.append(scratch_dirs.private_dir("ros2-course"))
        return _log_dir[0]


def start(label: str, argv: list[str], *, group: str = "node", env: dict | None = None,
          cwd: str | None = None, channel: bool = True, target: str = "",
          stop_signal: int = signal.SIGTERM) -> ChildProcess:
    """Start ``argv`` as the process ``label`` of ``group``; an old one with that label is stopped first.

    ``env`` adds to (or, with a value of None, removes from) the kernel's environment.
    ``channel`` gives the child a report pipe. ``stop_signal`` is what :meth:`ChildProcess.stop`
    sends first (SIGINT for programs written to stop on Ctrl+C, as ``ros2 run`` does).
    Build ``argv`` with :func:`python_target_argv` or :func:`program_argv`, so that the child
    dies with the kernel.
    """
    if not isinstance(label, str) or not label:
        raise CourseError(f"a process label must be a non-empty string, got {label!r}")
    stop([label], group=group)
    full_env = _environment(env)
    full_env[PARENT_ENV] = str(os.getpid())
    full_env["PYTHONUNBUFFERED"] = "1"
    full_env.setdefault("RCUTILS_COLORIZED_OUTPUT", "0")
    slot = port_slots.assign(full_env, log_dir())  # its own ports, never a killed child's (port_slots)
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in label)
    log_path = os.path.join(log_dir(), f"{group}-{safe}-{time.monotonic_ns()}.log")
    read_fd = write_fd = None
    if channel:
        read_fd, write_fd = os.pipe()
        full_env[CHANNEL_ENV] = str(write_fd)
    else:
        full_env.pop(CHANNEL_ENV, None)

    def fork() -> subprocess.Popen:
        with open(log_path, "wb") as log:
            return slot.start(lambda: subprocess.Popen(
                argv, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, env=full_env,
                cwd=cwd or os.getcwd(), start_new_session=True, pass_fds=(write_fd,) if channel else ()))

    try:
        process = _launcher.run(fork)
    except OSError as exc:
        if channel:
            os.close(read_fd)
            os.close(write_fd)
        raise CourseError(f"could not start {group} process {label!r} ({argv[0]}): {exc}") from None
    reader = None
    if channel:
        os.close(write_fd)
        reader = ChannelReader(read_fd, label)
    child = ChildProcess(label, group, argv, process, log_path, reader, target, stop_signal)
    with _lock:
        _registry[(group, label)] = child
    return child


def _environment(changes: dict | None) -> dict[str, str]:
    """The kernel's environment with ``changes`` applied (a value of None removes the variable)."""
    env = environment_snapshot()
    for key, value in (changes or {}).items():
        if value is None:
            env.pop(key, None)
        else:
            env[key] = str(value)
    return env


def run(argv: list[str], *, env: dict | None = None, cwd: str | None = None, timeout: float = 300.0,
        on_line: Callable[[str], None] | None = None, log=None) -> tuple[int, str]:
    """Run a command to its end (a build step), passing each output line to ``on_line``.

    Returns ``(exit code, everything it printed)``; the output is also written to the open text
    file ``log`` if given. A command still running after ``timeout`` seconds is killed with its
    whole process group (the compilers under a build tool too) and reported with
    :class:`CourseError`, also when a process that left the group still holds the output open.
    It dies with the kernel like every other child.
    """
    full_env = _environment(env)
    full_env.pop(CHANNEL_ENV, None)
    # the wrapper checks that its parent is this process: a PID inherited from whoever started this
    # process (a graded kernel's grader) would make it exit 0 at once, having run nothing
    full_env[PARENT_ENV] = str(os.getpid())

    def fork() -> subprocess.Popen:
        return subprocess.Popen(program_argv(argv[0], *argv[1:]), stdin=subprocess.DEVNULL,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=full_env,
                                cwd=cwd or os.getcwd(), start_new_session=True)

    try:
        process = _launcher.run(fork)
    except OSError as exc:
        raise CourseError(f"could not run {argv[0]}: {exc}") from None
    watch = ProcessGroup(process)
    lines: list[str] = []

    def emit(line: str) -> None:
        lines.append(line)
        if log is not None:
            log.write(line + "\n")
        if on_line is not None:
            on_line(line)

    try:
        timed_out = not _read_lines(process.stdout.fileno(), time.monotonic() + timeout, emit,
                                    on_timeout=lambda: watch.signal_group(signal.SIGKILL))
        if not watch.wait(0 if timed_out else STOP_GRACE_S):  # the output ended: so does the process
            watch.signal_group(signal.SIGKILL)
            watch.wait(KILL_WAIT_S)
    finally:
        watch.signal_group(signal.SIGKILL)  # nothing of the group outlives the step (a no-op if done)
        watch.wait(KILL_WAIT_S)
        watch.finish()
        process.stdout.close()
    if timed_out:
        raise CourseError(f"{os.path.basename(argv[0])} took longer than {timeout:g} s and was stopped. "
                          "Its last lines:\n" + "\n".join(lines[-20:]))
    return watch.code(), "\n".join(lines)


def _read_lines(fd: int, deadline: float, emit: Callable[[str], None],
                on_timeout: Callable[[], None]) -> bool:
    """Pass each line read from ``fd`` to ``emit`` until the end of the output; False on a timeout.

    Lines end with ``\\n``, ``\\r\\n`` or ``\\r`` (a progress line), as in text mode. At ``deadline``
    it calls ``on_timeout`` (which kills the writers) and reads what is left for :data:`DRAIN_S`
    more at the most: a writer outside the process group may keep the pipe open.
    """
    decoder = codecs.getincrementaldecoder("utf-8")(errors="replace")
    pending = ""
    finished = True
    with selectors.DefaultSelector() as selector:
        selector.register(fd, selectors.EVENT_READ)
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                if not finished:
                    break
                finished = False
                on_timeout()
                deadline = time.monotonic() + DRAIN_S
                continue
            if not selector.select(remaining):
                continue
            chunk = os.read(fd, 65536)
            if not chunk:
                break
            pending += decoder.decode(chunk)
            held = "\r" if pending.endswith("\r") else ""  # the \n of a \r\n may be in the next chunk
            *complete, pending = _universal(pending[:len(pending) - len(held)]).split("\n")
            pending += held
            for line in complete:
                emit(line)
    pending = _universal(pending + decoder.decode(b"", final=True)).removesuffix("\n")
    for line in pending.split("\n") if pending else ():
        emit(line)
    return finished


def _universal(text: str) -> str:
    return text.replace("\r\n", "\n").replace("\r", "\n")


# ---------------------------------------------------------------------- the registry
def running(group: str | None = None) -> dict[str, ChildProcess]:
    """The processes started and not yet stopped (of ``group`` only, if given), by label."""
    with _lock:
        return {label: child for (g, label), child in _registry.items() if group in (None, g)}


def get(label: str, group: str = "node") -> ChildProcess | None:
    """The process ``label`` of ``group``, if it was started and not stopped."""
    with _lock:
        return _registry.get((group, label))


def stop_together(children: list[ChildProcess], grace_s: float = STOP_GRACE_S) -> dict[str, int | None]:
    """SIGTERM to every child first, then wait for each: as long as the slowest, not the sum."""
    for child in children:
        child.request_stop()
    return {child.label: child.stop(grace_s) for child in children}


def stop(labels, group: str = "node", grace_s: float = STOP_GRACE_S) -> dict[str, int | None]:
    """Stop the processes ``labels`` of ``group`` together; exit codes by label (unknown labels skipped)."""
    with _lock:
        picked = [_registry.pop((group, label)) for label in labels if (group, label) in _registry]
    return stop_together(picked, grace_s)


def stop_all(grace_s: float = STOP_GRACE_S) -> None:
    """Stop every process the course started in this process."""
    with _lock:
        picked = list(_registry.values())
        _registry.clear()
    stop_together(picked, grace_s)


def _at_exit() -> None:
    stop_all(grace_s=1.0)
    with _lock:
        for folder in _log_dir:
            shutil.rmtree(folder, ignore_errors=True)
        _log_dir.clear()


atexit.register(_at_exit)
