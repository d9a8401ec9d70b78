"""The tests' servers and kernels get addresses that no other process can be handed at the same moment.

* :func:`tools.servers.free_port` picks a port below the range a bind to port 0 draws from (where every
  Jupyter kernel on TCP takes its five ports), and holds a lock on it that the other test processes
  respect;
* :mod:`tools.kernels` starts kernels on Unix sockets of their own; nbgrader's autograde uses them too.
"""

from __future__ import annotations

import subprocess
import sys

from tools.kernels import AsyncPrivateSocketKernelManager, PrivateSocketKernelManager
from tools.servers import _ephemeral_ports, free_port


def test_a_free_port_is_outside_the_range_that_port_zero_draws_from():
    ports = [free_port() for _ in range(20)]
    ephemeral = _ephemeral_ports()
    assert not [p for p in ports if p in ephemeral], (ports, ephemeral)
    assert len(set(ports)) == len(ports), ports


def test_another_process_is_not_handed_a_port_this_one_holds():
    held = free_port()
    # the other process takes the lock of exactly this port, as its free_port would try to
    probe = (
        "import fcntl, os, sys, tempfile\n"
        f"path = os.path.join(tempfile.gettempdir(), f'course-ports-{{os.getuid()}}', '{held}')\n"
        "handle = open(path, 'a')\n"
        "try:\n"
        "    fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)\n"
        "except BlockingIOError:\n"
        "    sys.exit(3)\n"
    )
    done = subprocess.run([sys.executable, "-c", probe], timeout=30)
    assert done.returncode == 3, "another process could take the lock of a port this process holds"


def test_kernel_managers_listen_on_sockets_of_their_own():
    first, second = PrivateSocketKernelManager(), AsyncPrivateSocketKernelManager()
    assert first.transport == second.transport == "ipc"
    assert first.ip != second.ip


def test_the_autograder_starts_its_kernels_on_sockets_of_their_own(tmp_path):
    from tools.grading.autograde_one import grading_config

    (tmp_path / "nbgrader_config.py").write_text("c = get_config()\n")
    config = grading_config(str(tmp_path))
    assert config.Execute.kernel_manager_class is AsyncPrivateSocketKernelManager


def test_every_notebook_client_starts_its_kernel_on_sockets_of_its_own():
    """A ``NotebookClient`` left with jupyter_client's TCP ports collided once in a fresh-clone CI run:
    the release's run of chapter 10's instructor source died with "Address already in use"."""
    import re
    from pathlib import Path

    repo = Path(__file__).resolve().parent.parent
    calls = {}
    sources = [path for folder in ("tools", "tests", "course_helpers")
               for path in repo.glob(f"{folder}/**/*.py")]
    for path in sources:
        text = path.read_text(encoding="utf-8")
        for match in re.finditer(r"NotebookClient\((?:[^()]|\([^()]*\))*\)", text):
            calls[f"{path.relative_to(repo)}:{text.count(chr(10), 0, match.start()) + 1}"] = match.group(0)
    assert len(calls) >= 4, calls  # the release, make execute and two working-copy tests at least
    private = "kernel_manager_class=AsyncPrivateSocketKernelManager"
    tcp = [where for where, call in calls.items() if private not in call]
    assert not tcp, f"NotebookClient on TCP ports at {tcp}: pass {private}"
