"""Shared fixtures: real rclpy nodes over real Fast DDS, one runtime per test process."""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import tempfile
import textwrap

import pytest

from course_helpers import get_runtime, shutdown_runtime
from course_helpers.core import verdict
from tests import timing_turns
from tests.browsers import HANG_MS, TEST_HANG_S

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture
def rt():
    """The process's course runtime, with the notebook-added nodes removed after each test."""
    runtime = get_runtime()
    yield runtime
    runtime.remove_all()
    for name in list(runtime.children()):
        runtime.stop_child(name)


@pytest.fixture(scope="session", autouse=True)
def _stop_runtime_at_end():
    yield
    shutdown_runtime()


EXEMPT_FROM_THE_STAGE_CHECK = ("timing", "makes_load", "grades_notebooks", "run_all", "image")
_RECORD_START = pytest.StashKey[int]()


def pytest_configure(config):
    """Each test process (every xdist worker) gets the file in which the processes it starts record
    the timing statements they judge (``course_helpers.core.verdict.TIMING_RECORD_VARIABLE``): set
    before any fixture starts a server, so that the server's kernels inherit it too."""
    handle, record = tempfile.mkstemp(prefix="course-timing-judged-", suffix=".jsonl")
    os.close(handle)
    os.environ[verdict.TIMING_RECORD_VARIABLE] = record
    timing_turns.open_turns(config)


def pytest_unconfigure(config):
    timing_turns.close_turns(config)
    record = os.environ.pop(verdict.TIMING_RECORD_VARIABLE, None)
    if record:
        with contextlib.suppress(FileNotFoundError):
            os.remove(record)


def pytest_collection_modifyitems(items):
    short = []  # a browser test's whole bound is longer than any one of its waits (tests/browsers.py)
    for item in items:
        if not item.get_closest_marker("browser"):
            continue
        bound = item.get_closest_marker("timeout")
        if bound is None:
            item.add_marker(pytest.mark.timeout(TEST_HANG_S))
        elif bound.args and bound.args[0] * 1000 <= HANG_MS:
            short.append(f"{item.nodeid} ({bound.args[0]} s)")
    if short:
        raise pytest.UsageError(f"a browser test's timeout must exceed one of its waits (HANG_MS = "
                                f"{HANG_MS} ms, tests/browsers.py): {', '.join(short)}")
    alone, shared = timing_turns.ALONE, timing_turns.SHARED
    loose = [item.nodeid for item in items
             if item.get_closest_marker(alone) and not item.get_closest_marker(shared)]
    if loose:
        raise pytest.UsageError(f"marked '{alone}' but not '{shared}' (it would run in the logic stage, "
                                f"beside everything): {', '.join(loose)}")


@pytest.hookimpl(hookwrapper=True, tryfirst=True)  # outside pytest-timeout's: waiting is not the test's time
def pytest_runtest_protocol(item, nextitem):
    """A timing test runs in its turn (tests/timing_turns.py): one marked 'runs_alone' while no other does."""
    if not item.get_closest_marker(timing_turns.SHARED):
        yield
        return
    with timing_turns.turn(alone=item.get_closest_marker(timing_turns.ALONE) is not None):
        yield


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    """Where the record stood before the test's fixtures (a module's too) were set up."""
    item.stash[_RECORD_START] = os.path.getsize(os.environ[verdict.TIMING_RECORD_VARIABLE])


@pytest.fixture(autouse=True)
def _time_is_judged_in_the_timing_stage(request):
    """A test that judges a measurement with the timing verdict must be marked 'timing'.

    The logic stage runs five workers on two cores; a measurement there may stay inconclusive for
    lack of CPU, which fails the test for a reason that is not its own. So whatever judges time in a
    test that is not marked fails at once, on any machine, naming the statement it judged: in the
    test's own process, in a process it or its fixtures started (the record of
    :func:`pytest_configure`), or in a kernel it ran code in over a server's websocket
    (:class:`tests.servers.KernelChannels`). A module fixture's judging counts for the test that
    set it up.

    Exempt are the verdict's own tests that make the machine busy on purpose ('makes_load': in the
    timing stage their busy loops would spoil the measurements of the worker beside them); the
    grading tests ('grades_notebooks'): nbgrader runs a chapter's lesson cells too, whose claims
    judge time, but it scores only the exercises' cells (tools/grading/results.py) and the release
    check prints a lesson's timing claim as a note (tools/assignments.lesson_cell_problem), so no
    verdict of theirs reads a timing claim; and the tests of the stages of their own ('run_all' for make
    test-browser, 'image' for make test-image), where every notebook runs as a student runs it.
    """
    if any(request.node.get_closest_marker(mark) for mark in EXEMPT_FROM_THE_STAGE_CHECK):
        yield
        return
    judged: list[str] = []
    verdict.TIMING_WATCHERS.append(judged.append)
    try:
        yield
    finally:
        verdict.TIMING_WATCHERS.remove(judged.append)
    with open(os.environ[verdict.TIMING_RECORD_VARIABLE], encoding="utf-8") as record:
        record.seek(request.node.stash[_RECORD_START])
        judged += [json.loads(line) for line in record if line.strip()]
    if judged:
        pytest.fail(f"this test judges time ({judged[0]!r}) but is not marked 'timing': mark it "
                    "(@pytest.mark.timing) so that it runs in make test's timing stage", pytrace=False)


def run_python(code: str, timeout: float = 60, env: dict | None = None):
    """Run a snippet in a fresh Python of this venv; return the CompletedProcess."""
    full_env = dict(os.environ)
    full_env.pop("ROS_DOMAIN_ID", None)  # let the child pick its own automatic domain
    full_env.update(env or {})
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
        timeout=timeout, env=full_env, cwd=REPO,
    )

