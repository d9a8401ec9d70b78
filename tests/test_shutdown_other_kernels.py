"""``rt.shutdown_other_kernels()`` through a real Jupyter server (issue 31, item 4).

A real JupyterLab server runs three kernels, each opened as JupyterLab opens a notebook (a session):

* 00's kernel, where the student calls ``rt.shutdown_other_kernels()``;
* 03's kernel, of the same user, with a course runtime, a node and a child-process node;
* a kernel of a second Unix user, started by the same server (its kernelspec drops to that user with
  ``setpriv`` before it becomes the kernel, so it is as much the server's child as the others), with a
  course runtime and a child-process node of its own.

The call must shut 03's kernel down through the server (the server no longer lists it; the kernel,
its node and its child process are gone) and say so in one line, and leave the other user's kernel and
its child, and 00's own kernel, running. Needs root (it creates the second user).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import tempfile
from pathlib import Path

import psutil
import pytest

from .servers import jupyter_lab
from .shared_install import closed_to_others, ensure_user, shared_venv

pytest.importorskip("websocket", reason="websocket-client is not installed")
pytestmark = pytest.mark.timeout(300)

REPO = Path(__file__).resolve().parent.parent
NEIGHBOUR = "r2cneighbour"  # the second user
COURSE_KERNEL = """
import json, os
from course_helpers import get_runtime
from course_helpers.nodes import Talker
rt = get_runtime()
child = rt.spawn('talker_{tag}', Talker, params={{'name': 'talker_{tag}'}}, wait_for='/talker_{tag}')
print(json.dumps({{'pid': os.getpid(), 'uid': os.getuid(), 'child': child.pid}}))
"""


def _facts(output: str) -> dict:
    return json.loads([line for line in output.splitlines() if line.startswith("{")][-1])


def _alive(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def _kernelspec(folder: Path, user, python: Path, home: Path) -> Path:
    """A kernelspec 'neighbour' under ``folder``/kernels: the kernel runs as ``user`` (same PID)."""
    spec = folder / "kernels" / "neighbour"
    spec.mkdir(parents=True)
    command = (f'chmod 0644 "$0" && exec setpriv --reuid={user.pw_uid} --regid={user.pw_gid} --clear-groups '
               f'{python} -m ipykernel_launcher -f "$0"')
    (spec / "kernel.json").write_text(json.dumps({
        "argv": ["sh", "-c", command, "{connection_file}"], "display_name": "neighbour", "language": "python",
        "env": {"HOME": str(home), "TMPDIR": str(home), "ROS_HOME": str(home / "ros"),
                "PYTHONPATH": str(REPO), "MPLCONFIGDIR": str(home / "mpl"),
                "IPYTHONDIR": str(home / "ipython")}}))
    return folder


def test_shutdown_other_kernels_stops_this_users_other_kernel_and_leaves_another_users():
    if os.geteuid() != 0 or shutil.which("useradd") is None or shutil.which("setpriv") is None:
        pytest.skip("needs root, useradd (passwd) and setpriv (util-linux): it runs a second user's kernel")
    blocked = closed_to_others(REPO / "course_helpers" / "__init__.py")
    if blocked:
        pytest.skip(f"the course at {REPO} is not readable by other users ({blocked} is closed)")
    workdir = Path(tempfile.mkdtemp(prefix="ros2-course-shutdown-", dir="/var/tmp"))
    workdir.chmod(0o755)
    user = ensure_user(NEIGHBOUR)
    try:
        python = shared_venv(workdir) / "bin" / "python"
        home = workdir / "home"
        home.mkdir()
        os.chown(home, user.pw_uid, user.pw_gid)
        share = _kernelspec(workdir / "share", user, python, home)
        # the neighbour's kernel runs as another user, who may not make sockets in the runtime folder
        with jupyter_lab(env={"JUPYTER_PATH": str(share)}, kernel_transport="tcp") as lab:
            for folder in (lab.folder, lab.folder / "runtime"):  # the neighbour reads its connection file
                folder.chmod(0o755)
            mine, mine_channels = lab.open_notebook("00_welcome.ipynb")
            other, other_channels = lab.open_notebook("03_topics.ipynb")
            theirs, their_channels = lab.open_notebook("08b_qos_lab.ipynb", kernel="neighbour")
            other_facts = _facts(other_channels.run(COURSE_KERNEL.format(tag="mine")))
            their_facts = _facts(their_channels.run(COURSE_KERNEL.format(tag="theirs")))
            assert their_facts["uid"] == user.pw_uid, their_facts
            server = psutil.Process(lab.server.pid)
            kernels = {p.pid for p in server.children()}
            assert {other_facts["pid"], their_facts["pid"]} <= kernels, (kernels, other_facts, their_facts)

            said = mine_channels.run("from course_helpers import get_runtime\nrt = get_runtime()\n"
                                     "done = rt.shutdown_other_kernels()\nprint(len(done))")
            print(said)
            lines = [line for line in said.splitlines() if line.startswith("[course] Shut down")]
            assert lines == ["[course] Shut down 1 other course kernel of this Jupyter server "
                             "(03_topics.ipynb): its nodes and 1 child process stopped."], said
            assert said.strip().endswith("1"), said
            listed = {kernel["id"] for kernel in lab.api("/api/kernels")}
            assert other not in listed and {mine, theirs} <= listed, listed
            assert not _alive(other_facts["pid"]) and not _alive(other_facts["child"]), other_facts
            # the other user's kernel and its child, and this kernel, run on
            assert _alive(their_facts["pid"]) and _alive(their_facts["child"]), their_facts
            assert re.fullmatch(r"\d+\n", their_channels.run("print(len(rt.nodes()))"))
            again = mine_channels.run("rt.shutdown_other_kernels()")
            assert again.startswith("[course] No other course kernel of this Jupyter server"), again
            for channels in (mine_channels, other_channels, their_channels):
                channels.close()
    finally:
        for process in psutil.process_iter(["uids"]):
            if process.info["uids"] and process.info["uids"].real == user.pw_uid:
                try:
                    process.send_signal(signal.SIGKILL)
                except psutil.Error:
                    pass
        shutil.rmtree(workdir, ignore_errors=True)
