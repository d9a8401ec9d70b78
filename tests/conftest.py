"""Shared fixtures: real rclpy nodes over real Fast DDS, one runtime per test process."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from course_helpers import get_runtime, shutdown_runtime
from course_helpers.core import verdict

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


@pytest.fixture(autouse=True)
def _time_is_judged_in_the_timing_stage(request):
    """A test that judges a measurement with the timing verdict must be marked 'timing'.

    The logic stage runs five workers on two cores; a measurement there may stay inconclusive for
    lack of CPU, which fails the test for a reason that is not its own. So whatever judges time in a
    test that is not marked fails at once, on any machine, naming the statement it judged. The
    verdict's own tests that make the machine busy on purpose are marked 'makes_load' instead: in
    the timing stage their busy loops would spoil the measurements of the worker beside them.
    """
    if any(request.node.get_closest_marker(mark) for mark in ("timing", "makes_load")):
        yield
        return
    judged: list[str] = []
    verdict.TIMING_WATCHERS.append(judged.append)
    try:
        yield
    finally:
        verdict.TIMING_WATCHERS.remove(judged.append)
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

