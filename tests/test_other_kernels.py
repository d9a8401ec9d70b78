"""A runtime that starts while another notebook of the same Jupyter server runs ROS says so (issue 22,
item 6), with real kernels: both are children of this test process, as a server's kernels are of it."""

from __future__ import annotations

import ast
import os
import signal
import subprocess
import sys

import pytest

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
        assert "Running panel" in lines[0] and "rt.shutdown_other_kernels()" in lines[0], lines
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


HOLD_A_DOMAIN = """
import time
from course_helpers.core.domains import reserve_domain
print(reserve_domain(), flush=True)
time.sleep(60)
"""

# The same reservation made by a bare Python (another user cannot run this venv's), free domain first.
HOLD_A_DOMAIN_BARE = """
import socket, time
for domain in range(101, 0, -1):
    sock = socket.socket(socket.AF_UNIX)
    try:
        sock.bind(b'\\0ros2-course-domain-%d' % domain)
    except OSError:
        continue
    sock.listen(1)
    print(domain, flush=True)
    time.sleep(60)
"""

# A holder that is not a sibling (as a kernel of another Jupyter server): a child of a child.
HOLD_ONE_LEVEL_DOWN = f"""
import subprocess, sys
holder = subprocess.Popen([sys.executable, '-c', {HOLD_A_DOMAIN!r}], stdout=subprocess.PIPE, text=True)
print(holder.pid, holder.stdout.readline().strip(), flush=True)
holder.wait()
"""

ASK = """
from course_helpers.core.other_kernels import other_kernels
print([kernel.describe() for kernel in other_kernels()])
print(sorted(kernel.pid for kernel in other_kernels(machine_wide=True)))
"""


def test_only_this_users_processes_of_the_same_parent_count():
    """Siblings that hold a course domain count (named 'a process' without a notebook or a kernel);
    machine-wide, this user's holders further away count too (kernels of other Jupyter servers);
    another user's process holding one never does, whatever it holds."""
    started = [subprocess.Popen([sys.executable, "-c", HOLD_A_DOMAIN], stdout=subprocess.PIPE, text=True),
               subprocess.Popen([sys.executable, "-c", HOLD_ONE_LEVEL_DOWN], stdout=subprocess.PIPE,
                                text=True)]
    foreign = None
    if os.getuid() == 0:  # only root can start a process of another user next to its own
        foreign = subprocess.Popen(["/usr/bin/python3", "-c", HOLD_A_DOMAIN_BARE], stdout=subprocess.PIPE,
                                   text=True, user="nobody", cwd="/")
        started.append(foreign)
    further = None
    try:
        domains = [proc.stdout.readline().split() for proc in started]
        further = int(domains[1][0])  # the holder below the second process
        asked = subprocess.run([sys.executable, "-c", ASK], capture_output=True, text=True, timeout=60)
        assert asked.returncode == 0, asked.stderr
        same_server, machine_wide = asked.stdout.strip().splitlines()
        expected = f"['a process (pid {started[0].pid} in domain {domains[0][0]})']"
        assert same_server == expected, (asked.stdout, domains)
        machine = set(ast.literal_eval(machine_wide))
        assert {started[0].pid, further} <= machine, (machine_wide, started[0].pid, further)
        assert started[1].pid not in machine  # it holds no domain itself
        if foreign is None:
            pytest.skip("not root: no process of another user to check (the rest passed)")
        assert foreign.pid not in machine, (machine_wide, foreign.pid)
    finally:
        if further is not None:
            os.kill(further, signal.SIGKILL)
        for proc in started:
            proc.kill()
            proc.wait(timeout=10)
