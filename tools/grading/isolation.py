"""One student's grading run, kept apart from every other one.

Each submission is graded by a process of its own (``autograde_one``) whose environment
:func:`student_env` builds: a fresh temporary folder for everything it writes outside its
own autograded folder (``TMPDIR``, ROS logs, Jupyter runtime files, matplotlib), no
``ROS_DOMAIN_ID`` (so the course kernel reserves a domain of its own, like every course
kernel), the student build of ``course_helpers`` (no reference solutions to import), and a
marker variable. After the run :func:`sweep` kills whatever is left - descendants of the
grader (a child subreaper, so detached processes come back to it) and any process carrying
the marker - and :func:`domains_left` checks that the domains the kernel held are free.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import tempfile
import uuid
from dataclasses import dataclass, field

import psutil

from course_helpers.core.domains import domain_free, domain_holders
from tools.grading.source import REPO

PR_SET_CHILD_SUBREAPER = 36
MARKER = "COURSE_GRADING_RUN"


def become_subreaper() -> None:
    """Orphaned descendants are re-parented to this process instead of init (Linux)."""
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "prctl(PR_SET_CHILD_SUBREAPER) failed")


@dataclass
class Run:
    """One student's run: its marker, temporary folder and run record."""

    student: str
    marker: str = field(default_factory=lambda: uuid.uuid4().hex)
    tmp: str = ""
    record: str = ""

    def __post_init__(self) -> None:
        self.tmp = tempfile.mkdtemp(prefix=f"course-grading-{self.student}-")
        self.record = os.path.join(self.tmp, "run-record.json")


def student_env(run: Run, student_build: str) -> dict[str, str | None]:
    """Environment changes for ``run`` (a value of None removes the variable)."""
    folders = {name: os.path.join(run.tmp, name) for name in ("tmp", "ros", "runtime", "mpl")}
    for path in folders.values():
        os.makedirs(path, exist_ok=True)
    return {
        MARKER: run.marker,
        "TMPDIR": folders["tmp"],
        "ROS_HOME": folders["ros"],
        "ROS_LOG_DIR": os.path.join(folders["ros"], "log"),
        "JUPYTER_RUNTIME_DIR": folders["runtime"],
        "MPLCONFIGDIR": folders["mpl"],
        # the student build first (its course_helpers has no solutions), then this checkout's root, so
        # that the grader imports this checkout's tools.grading (the editable install's path may name
        # another checkout of the course)
        "PYTHONPATH": os.pathsep.join([student_build, str(REPO)]),
        "ROS_DOMAIN_ID": None,
        "COURSE_PARENT_PID": None,
    }


def _describe(proc: psutil.Process) -> str:
    try:
        return f"pid {proc.pid}: {' '.join(proc.cmdline())[:120] or proc.name()}"
    except psutil.Error:
        return f"pid {proc.pid}"


def kill_all(procs: list[psutil.Process]) -> list[str]:
    """Kill ``procs`` at once and wait up to 5 s for them to go; return their descriptions."""
    described = [_describe(p) for p in procs]
    for proc in procs:
        try:
            proc.kill()
        except psutil.Error:
            pass
    psutil.wait_procs(procs, timeout=5)
    return described


def _carries(proc: psutil.Process, marker: str) -> bool:
    try:
        return proc.environ().get(MARKER) == marker
    except psutil.Error:
        return False


def leftovers(marker: str) -> list[psutil.Process]:
    """Processes of a finished run: this process's descendants and every process with its marker."""
    found = {p.pid: p for p in psutil.Process().children(recursive=True)}
    for proc in psutil.process_iter():
        if proc.pid not in found and proc.pid != os.getpid() and _carries(proc, marker):
            found[proc.pid] = proc
    alive = []
    for proc in found.values():
        try:
            if proc.status() != psutil.STATUS_ZOMBIE:
                alive.append(proc)
        except psutil.Error:
            pass
    return alive


def sweep_descendants() -> list[str]:
    """Kill this process's descendants that are still running; return their descriptions."""
    alive = []
    for proc in psutil.Process().children(recursive=True):
        try:
            if proc.status() != psutil.STATUS_ZOMBIE:
                alive.append(proc)
        except psutil.Error:
            pass
    return kill_all(alive)


def sweep(marker: str) -> list[str]:
    """Kill what a finished run left running; return their descriptions (empty when nothing was left)."""
    procs = leftovers(marker)
    described = kill_all(procs)
    for child in psutil.Process().children():  # reap re-parented zombies
        try:
            if child.status() == psutil.STATUS_ZOMBIE:
                os.waitpid(child.pid, os.WNOHANG)
        except (psutil.Error, ChildProcessError):
            pass
    return described


def domains_left(domains: list[int], marker: str) -> list[int]:
    """The domains of ``domains`` still held by a process of the run (none after a clean sweep).

    A domain another course kernel reserved in the meantime is not the run's: only holders
    carrying the run's marker count.
    """
    held = []
    for domain in domains:
        if domain_free(domain):
            continue
        for pid in domain_holders(domain):
            try:
                if _carries(psutil.Process(pid), marker):
                    held.append(domain)
                    break
            except psutil.Error:
                continue
    return held


def remove_tmp(run: Run) -> bool:
    """Delete the run's temporary folder; True if it is gone."""
    shutil.rmtree(run.tmp, ignore_errors=True)
    return not os.path.exists(run.tmp)
