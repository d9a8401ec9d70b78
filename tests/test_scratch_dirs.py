"""A killed process's folders are removed by the next course process; nobody else's are touched.

Real processes in a temporary directory of the test's own (``TMPDIR``): one is killed with SIGKILL
(its ``atexit`` never runs), one stays alive, and a folder of a dead process belongs to another
Unix user. The next process that asks for its log folder removes only the killed one's.
"""

from __future__ import annotations

import os
import pwd
import signal
import subprocess
import sys

import pytest

from course_helpers.core import scratch_dirs

LOG_DIR = "from course_helpers.core import processes; print(processes.log_dir(), flush=True)"


def _start(tmp_path, code: str) -> tuple[subprocess.Popen, str]:
    """A Python process with ``TMPDIR=tmp_path`` that runs ``code``, and the first line it prints."""
    child = subprocess.Popen([sys.executable, "-c", code], env=dict(os.environ, TMPDIR=str(tmp_path)),
                             stdout=subprocess.PIPE, text=True)
    return child, child.stdout.readline().strip()


def _dead_pid() -> int:
    child = subprocess.Popen(["true"])
    child.wait()
    return child.pid


def test_the_log_folder_of_a_killed_process_is_removed_by_the_next_one_and_a_live_ones_kept(tmp_path):
    killed, killed_dir = _start(tmp_path, LOG_DIR + "; import time; time.sleep(600)")
    alive, alive_dir = _start(tmp_path, LOG_DIR + "; import time; time.sleep(600)")
    try:
        assert os.path.basename(killed_dir).startswith(f"ros2-course-{os.stat('/proc/self/ns/pid').st_ino}"
                                                       f"-{killed.pid}-"), killed_dir
        killed.send_signal(signal.SIGKILL)
        killed.wait()
        assert os.path.isdir(killed_dir)  # a killed process cannot remove its own folder
        old_style = tmp_path / "ros2-course-abc123"  # an older course's name: no owner to check
        old_style.mkdir()
        following, next_dir = _start(tmp_path, LOG_DIR)
        assert following.wait(timeout=60) == 0
        assert os.path.dirname(next_dir) == str(tmp_path)
        assert not os.path.exists(killed_dir)
        assert os.path.isdir(alive_dir) and old_style.is_dir()
        assert not os.path.exists(next_dir)  # the next process exited normally: removed its own
    finally:
        alive.kill()
        alive.wait()


def test_a_sweep_removes_only_the_kind_it_was_asked_for(tmp_path):
    dead = _dead_pid()
    namespace = os.stat("/proc/self/ns/pid").st_ino
    ours = tmp_path / f"ch09_interfaces-{namespace}-{dead}-x"
    other_kind = tmp_path / f"other-{namespace}-{dead}-x"
    other_namespace = tmp_path / f"ch09_interfaces-{namespace + 1}-{dead}-x"  # another container's pid
    for folder in (ours, other_kind, other_namespace):
        folder.mkdir()
    assert scratch_dirs.sweep("ch09_interfaces", parent=str(tmp_path)) == [str(ours)]
    assert other_kind.is_dir() and other_namespace.is_dir()


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to make a folder another user owns")
def test_a_dead_processs_folder_that_another_user_owns_is_kept(tmp_path):
    folder = tmp_path / f"ros2-course-{os.stat('/proc/self/ns/pid').st_ino}-{_dead_pid()}-x"
    folder.mkdir()
    nobody = pwd.getpwnam("nobody")
    os.chown(folder, nobody.pw_uid, nobody.pw_gid)
    assert scratch_dirs.sweep("ros2-course", parent=str(tmp_path)) == []
    assert folder.is_dir()
