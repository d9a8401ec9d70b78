"""What keeps a child's whole process tree together, even when the kernel dies (see :mod:`.processes`).

Every course child starts in a session and process group of its own, with the kernel as its
parent. While the kernel lives, it signals that whole group (stop, timeout, kill). For the
moment the kernel dies, however it dies (SIGKILL included), each child is set up here:

* **Die with the parent.** Linux sends the child SIGTERM when the kernel's launcher thread ends
  (``PR_SET_PDEATHSIG``); a child whose kernel is already gone exits at once.
* **A program keeps a supervisor.** A program (``processes.program_argv``: colcon-built nodes,
  the discovery server, build steps) does not replace the course's child: the child stays as the
  program's parent, a small Python process with nothing imported beyond this module, waiting in
  ``sigwaitinfo`` (no CPU). When the kernel dies it passes the signal on to its group and kills
  what is left after :data:`CLEANUP_S`; when the program ends it ends what the program left
  running, and exits with the program's own status (the same code, or the same signal).
  ``PR_SET_PDEATHSIG`` alone covers only the program, not the compilers or background jobs
  below it.
* **Orphans come back.** The child is a child subreaper (``PR_SET_CHILD_SUBREAPER``): a
  descendant whose parent exits, or that left the group with ``setsid``, is re-parented to the
  child instead of to init, so :func:`end_descendants` still finds it.

A Python target (``rt.spawn``) runs in the child itself (its PID is the one in its DDS GUIDs), so
it supervises itself: it is a subreaper too and ends its descendants when it exits.
"""

from __future__ import annotations

import ctypes
import os
import resource
import signal
import time

PARENT_ENV = "COURSE_PARENT_PID"
PR_SET_PDEATHSIG = 1
PR_SET_CHILD_SUBREAPER = 36
STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)
CLEANUP_S = 10.0  # s; once the kernel is gone, how long a tree may take to stop before SIGKILL
LEFTOVER_GRACE_S = 1.0  # s; what a finished program left running gets this long after SIGTERM
EXEC_FAILED = 127  # the exit code of a program that could not be started (as a shell's)


def _prctl(option: int, value: int) -> bool:
    try:
        return ctypes.CDLL(None, use_errno=True).prctl(option, value, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def die_with_parent() -> None:
    """Ask Linux for SIGTERM when the kernel that started this process dies; exit if it is gone."""
    _prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    if orphaned():
        os._exit(0)


def orphaned() -> bool:
    """True if the kernel that started this process is gone (this process was re-parented)."""
    expected = os.environ.get(PARENT_ENV)
    return expected is not None and os.getppid() != int(expected)


def become_subreaper() -> None:
    """Orphaned descendants are re-parented to this process, not to init (Linux 3.4 and later)."""
    _prctl(PR_SET_CHILD_SUBREAPER, 1)


def end_descendants(grace_s: float = LEFTOVER_GRACE_S) -> int:
    """SIGTERM every descendant of this process, SIGKILL those left after ``grace_s``, reap them.

    ``grace_s`` 0 kills at once. Returns how many there were. A descendant started while this
    runs is caught by the second look.
    """
    if not _has_children():
        return 0  # a subreaper without children has no descendants: every orphan would be its child
    import psutil

    found = 0
    for _look in range(2):
        try:
            procs = psutil.Process().children(recursive=True)
        except psutil.Error:
            return found
        if not procs:
            break
        found += len(procs)
        steps = [(signal.SIGTERM, grace_s)] if grace_s > 0 else []
        for sig, wait_s in [*steps, (signal.SIGKILL, 1.0)]:
            for proc in procs:
                try:
                    proc.send_signal(sig)  # psutil checks that the PID still names the same process
                except psutil.Error:
                    pass
            _gone, procs = psutil.wait_procs(procs, timeout=wait_s)  # reaps those that are our children
            if not procs:
                break
    return found


def _has_children() -> bool:
    try:
        os.waitid(os.P_ALL, 0, os.WEXITED | os.WNOHANG | os.WNOWAIT)
    except ChildProcessError:
        return False
    return True


def supervise(program: str, args: list[str], before_exec) -> None:
    """Run ``program`` as this process's only child and supervise it; never returns.

    ``before_exec()`` runs in both processes before the program starts (it drops what the
    program must not inherit, such as the report channel). Exits with the program's status.
    """
    parent = os.getppid()
    watched = {signal.SIGCHLD, *STOP_SIGNALS}
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, watched)  # taken by sigwaitinfo only
    supervisor = os.getpid()
    pid = os.fork()
    if pid == 0:
        try:
            signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
            for name in ("SIGPIPE", "SIGXFSZ"):  # Python ignores them; a program gets the defaults
                signal.signal(getattr(signal, name), signal.SIG_DFL)
            _prctl(PR_SET_PDEATHSIG, signal.SIGTERM)  # a killed supervisor takes its program along
            if os.getppid() != supervisor:
                os._exit(0)
            before_exec()
            os.execvp(program, [program, *args])  # searches PATH, like a shell
        except BaseException as exc:
            os.write(2, f"course child: cannot run {program}: {exc}\n".encode(errors="replace"))
        os._exit(EXEC_FAILED)
    before_exec()
    status = _wait_for_program(pid, parent, watched)
    end_descendants()
    _exit_like(status)


def _wait_for_program(pid: int, parent: int, watched: set) -> int:
    """Wait for the program's exit; pass a stop signal on when the kernel did not send it to the group.

    The kernel signals the whole group, so a signal from it needs nothing more. After the kernel's
    death (or a signal from anyone else) the signal goes to the group, and everything still running
    :data:`CLEANUP_S` later is killed.
    """
    deadline = None
    passed_on = False
    while True:
        if deadline is None:
            info = signal.sigwaitinfo(watched)
        else:
            info = signal.sigtimedwait(watched, max(0.0, deadline - time.monotonic()))
            if info is None:  # the tree outlived the clean-up time
                end_descendants(0)
                deadline = None
                continue
        if info.si_signo == signal.SIGCHLD:
            status = _reap(pid)
            if status is not None:
                return status
        elif not passed_on and info.si_pid != os.getpid() and (info.si_pid != parent or orphaned()):
            passed_on = True
            os.killpg(0, info.si_signo)  # our own copy comes back pending, and is ignored
            deadline = time.monotonic() + CLEANUP_S


def _reap(pid: int) -> int | None:
    """Reap every exited child (orphans included); the program's wait status if it is one of them."""
    status = None
    while True:
        try:
            reaped, code = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return status
        if reaped == 0:
            return status
        if reaped == pid:
            status = code


def _exit_like(status: int) -> None:
    """End this process as the program ended: with its exit code, or by its signal (no core dump)."""
    code = os.waitstatus_to_exitcode(status)
    if code >= 0:
        os._exit(code)
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    signal.signal(-code, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {-code})
    os.kill(os.getpid(), -code)
    os._exit(128 - code)
