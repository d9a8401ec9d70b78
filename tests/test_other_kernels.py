"""A runtime that starts while another notebook of the same Jupyter server runs ROS says so (issue 22,
item 6), with real kernels: both are children of this test process, as a server's kernels are of it."""

from __future__ import annotations

import os

from .conftest import REPO
from .kernel_session import KernelSession

NOTEBOOKS = os.path.join(REPO, "notebooks")

BUSY_NOTEBOOK = """
from course_helpers import get_runtime
from course_helpers.nodes import Relay, Talker
rt = get_runtime()
rt.add(Talker, console=False)
rt.spawn('relay', Relay, wait_for='/relay')
print('domain', rt.domain.domain_id)
"""

OTHERS = "print('others', rt.status()['other_kernels'])"


def test_a_new_runtime_names_the_other_notebooks_that_run_ros():
    busy = KernelSession(cwd=NOTEBOOKS, env={"JPY_SESSION_NAME": os.path.join(NOTEBOOKS, "03_topics.ipynb")})
    new = None
    try:
        out, error = busy.run(BUSY_NOTEBOOK)
        assert error is None, out
        assert "[course]" not in out, out  # nothing else of this "server" ran ROS when it started
        domain = int(out.split("domain ")[1].split()[0])
        new = KernelSession(cwd=NOTEBOOKS)
        # A kernel that has not started a runtime is not one: the busy notebook sees no other.
        out, error = busy.run(OTHERS)
        assert error is None and "others []" in out, out

        out, error = new.run("from course_helpers import get_runtime\nrt = get_runtime()\n" + OTHERS)
        assert error is None, out
        described = f"03_topics.ipynb (pid {busy.process.pid} in domain {domain} with 1 child process)"
        lines = [line for line in out.splitlines() if line.startswith("[course]")]
        assert len(lines) == 1, out
        expected = f"[course] 1 other notebook of this Jupyter server runs ROS: {described}."
        assert lines[0].startswith(expected), lines
        assert "Running panel" in lines[0] and "Kernel > Shut Down Kernel" in lines[0], lines
        assert f"others [{described!r}]" in out, out
        out, error = new.run("rt.show_status()")
        assert f"other_kernels      {described}" in out.splitlines(), out
        # Getting the runtime again says nothing new; the busy notebook now sees the new one.
        out, error = new.run("rt = get_runtime()")
        assert error is None and out == "", out
        out, error = busy.run(OTHERS)
        assert f"'a kernel (pid {new.process.pid} in domain" in out, out

        busy.shutdown()
        out, error = new.run(OTHERS)
        assert error is None and "others []" in out, out
    finally:
        busy.shutdown()
        if new is not None:
            new.shutdown()
