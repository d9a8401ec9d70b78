"""Shared fixtures: real rclpy nodes over real Fast DDS, one runtime per test process."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from course_helpers import get_runtime, shutdown_runtime

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


def run_python(code: str, timeout: float = 60, env: dict | None = None):
    """Run a snippet in a fresh Python of this venv; return the CompletedProcess."""
    full_env = dict(os.environ)
    full_env.pop("ROS_DOMAIN_ID", None)  # let the child pick its own automatic domain
    full_env.update(env or {})
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
        timeout=timeout, env=full_env, cwd=REPO,
    )

