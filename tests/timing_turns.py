"""Turns in the timing stage: a test that loads the machine by design runs while no other test runs.

The timing stage runs two workers, one per core, so that a measurement has a core to itself. A few of
its tests load the machine on purpose or by what they are: a hub with three students' kernels, a
JupyterLab with Chromium, the QoS lab beside a CPU hog and another kernel's nodes. Beside one of them
the other worker's measurement is starved and can end inconclusive (fresh-clone run Z10: chapter 03's
throughput check, "this one waited for a CPU 432% of the 4.5 s; 4 other course kernels"). Those
tests are marked ``runs_alone`` as well as ``timing``.

Every timing test holds a shared lock on one file for as long as it runs (set-up, call and teardown);
a ``runs_alone`` test holds it exclusively. A turnstile lock taken before either keeps a waiting
``runs_alone`` test from being overtaken by the other worker's next tests. The locks are ``flock``
locks on files in a folder that the pytest process at the root of a run (not an xdist worker) makes
private (``mkdtemp``) and names to its workers in ``TURNS_VARIABLE``; a pytest run inside a test makes
its own. The kernel drops a lock when its process dies, so a killed worker never leaves the stage
waiting.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import tempfile
from collections.abc import Iterator

TURNS_VARIABLE = "COURSE_TIMING_TURNS"
SHARED, ALONE = "timing", "runs_alone"  # the marks
STAGE, TURNSTILE = "stage", "turnstile"  # the lock files


def open_turns(config) -> None:
    """In the run's root process, make the folder of the locks; a worker uses its root's."""
    if not hasattr(config, "workerinput"):
        os.environ[TURNS_VARIABLE] = tempfile.mkdtemp(prefix="course-timing-turns-")


def close_turns(config) -> None:
    if not hasattr(config, "workerinput"):
        shutil.rmtree(os.environ.pop(TURNS_VARIABLE), ignore_errors=True)


def open_lock(name: str) -> int:
    """A descriptor of the lock file ``name`` (STAGE or TURNSTILE) of this run's turns."""
    return os.open(os.path.join(os.environ[TURNS_VARIABLE], name), os.O_RDWR | os.O_CREAT, 0o600)


@contextlib.contextmanager
def _locked(name: str, how: int) -> Iterator[None]:
    fd = open_lock(name)
    try:
        fcntl.flock(fd, how)
        yield
    finally:
        os.close(fd)  # closing drops the lock


@contextlib.contextmanager
def turn(alone: bool) -> Iterator[None]:
    """Hold the stage's lock for one test: exclusively if it runs alone, shared otherwise."""
    with contextlib.ExitStack() as stage:
        with _locked(TURNSTILE, fcntl.LOCK_EX):
            stage.enter_context(_locked(STAGE, fcntl.LOCK_EX if alone else fcntl.LOCK_SH))
        yield
