"""The classroom server (issue 14): a real JupyterHub with classroom/jupyterhub_config.py.

Three Unix users are created (useradd, so the test needs root; it is skipped otherwise), the hub
is started on localhost with the course's config plus a test authenticator (a shared password)
and an API token, and each student's server is started through the hub's REST API. Through each
server (its sessions, contents and kernel websocket APIs, behind the hub's proxy) notebook 00 of
the student's working copy runs in a kernel: the three kernels take their domains at the same
time, then run the rest in turn (its cells judge time, so the test is in the timing stage). Then
every kernel adds a node and spawns a child-process node: the kernels must hold three different
ROS domains, each must see its own nodes and none of the others' (from inside, and from a probe
outside), the course must be read-only for them, and stopping a server must leave no process of that student
(no kernel, no ROS child) and must free its domain.

The course venv must be runnable by other users. This repository's .venv usually is not (its
Python links into /root, which is closed), so, as an instructor would install the course with a
system Python (docs/classroom.md), the test makes a shared install: a hard-linked copy of .venv
under /var/tmp whose interpreter is the system Python of the same version. Nothing under /root
is opened up. configurable-http-proxy comes from npm:
``npm install --prefix .venv/node configurable-http-proxy@5.3.0``.
"""

from __future__ import annotations

import json
import os
import pwd
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from course_helpers.core.dds_config import udp_loopback_env
from course_helpers.core.domains import domain_free, domain_holders
from course_helpers.core.waiting import poll_until
from tools.servers import free_port

from .servers import KernelChannels, jupyterhub
from .shared_install import closed_to_others as _closed_to_others
from .shared_install import shared_venv as _shared_venv

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / "classroom" / "jupyterhub_config.py"
STUDENTS = ("r2cstudent1", "r2cstudent2", "r2cstudent3")
NOTEBOOK = "00_welcome.ipynb"
CELL_TIMEOUT_S = 120
ARTIFACTS = REPO / "tests" / "artifacts"  # classroom_hub.json: the measured figures of the last run
LOCAL_PROXY = REPO / ".venv" / "node" / "node_modules" / ".bin" / "configurable-http-proxy"

requests = pytest.importorskip("requests", reason="requests is not installed")
websocket = pytest.importorskip("websocket", reason="websocket-client is not installed")
pytest.importorskip("jupyterhub", reason="JupyterHub (PyPI: jupyterhub==6.1.1) is not installed")

pytestmark = pytest.mark.timeout(300)


def _proxy() -> str | None:
    found = os.environ.get("ROS2_COURSE_PROXY") or shutil.which("configurable-http-proxy")
    return found or (str(LOCAL_PROXY) if LOCAL_PROXY.exists() else None)


def _remove_user(name: str) -> None:
    try:
        uid = pwd.getpwnam(name).pw_uid
    except KeyError:
        return
    for pid in _pids_of(uid):  # anything the test started as this user and left behind
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    subprocess.run(["userdel", "-r", name], capture_output=True, timeout=30)


def _pids_of(uid: int) -> list[int]:
    import psutil

    found = []
    for process in psutil.process_iter(["uids", "pid"]):
        uids = process.info["uids"]
        if uids is not None and uid in (uids.real, uids.effective):
            found.append(process.info["pid"])
    return found


def _memory_mb(uid: int) -> float:
    """Resident memory of all of a user's processes (server, kernel, ROS children), in MB."""
    import psutil

    total = 0
    for pid in _pids_of(uid):
        try:
            total += psutil.Process(pid).memory_info().rss
        except psutil.Error:
            pass
    return round(total / 1e6, 1)


def _describe(pids: list[int]) -> list[str]:
    """Each process's command line, state and what its threads wait in (for a failure message)."""
    import psutil

    described = []
    for pid in pids:
        try:
            process = psutil.Process(pid)
            waits = sorted({Path(f"/proc/{pid}/task/{t.id}/wchan").read_text() for t in process.threads()})
            described.append(f"{pid} ({process.status()}, parent {process.ppid()}, waiting in {waits}): "
                             f"{' '.join(process.cmdline())[:160]}")
        except (psutil.Error, OSError):
            pass
    return described


class Hub:
    """The running hub: its base URL and a service token with admin rights over users and servers."""

    def __init__(self, base: str, token: str, log: Path):
        self.base, self.token, self.log = base, token, log
        self.password = ""
        self.http = requests.Session()
        self.http.headers["Authorization"] = f"token {token}"

    def api(self, method: str, path: str, **kwargs):
        response = self.http.request(method, f"{self.base}/hub/api{path}", timeout=30, **kwargs)
        assert response.status_code < 400, f"{method} {path}: {response.status_code} {response.text}"
        return response.json() if response.content else None

    def server(self, user: str) -> dict | None:
        return self.api("GET", f"/users/{user}")["servers"].get("")

    def log_tail(self) -> str:
        return self.log.read_text(errors="replace")[-4000:]


@pytest.fixture
def hub(tmp_path_factory):
    if os.geteuid() != 0:
        pytest.skip("needs root: the classroom test creates Unix users (useradd) and runs their servers")
    if shutil.which("useradd") is None or shutil.which("userdel") is None:
        pytest.skip("useradd/userdel are missing (package passwd)")
    proxy = _proxy()
    if proxy is None:
        pytest.skip("configurable-http-proxy is missing: npm install --prefix .venv/node "
                    "configurable-http-proxy@5.3.0 (or npm install -g, or set ROS2_COURSE_PROXY)")
    blocked = _closed_to_others(REPO / "tools" / "working_copy.py")
    if blocked:
        pytest.skip(f"the course at {REPO} is not readable by other users ({blocked} is closed)")
    workdir = Path(tempfile.mkdtemp(prefix="ros2-course-classroom-", dir="/var/tmp"))
    workdir.chmod(0o755)
    try:
        venv = _shared_venv(workdir)
    except BaseException:
        shutil.rmtree(workdir, ignore_errors=True)
        raise
    state = workdir / "hub"
    state.mkdir(mode=0o700)
    for name in STUDENTS:
        _remove_user(name)  # left over from an interrupted run
        subprocess.run(["useradd", "--create-home", "--shell", "/bin/bash", name], check=True,
                       capture_output=True, timeout=30)
    port, token, password = free_port(), secrets.token_hex(32), secrets.token_hex(8)
    test_config = state / "test_config.py"
    test_config.write_text(f"""
load_subconfig({str(CONFIG)!r})  # the classroom config as instructors use it, then the test's parts
c.JupyterHub.authenticator_class = "shared-password"
c.SharedPasswordAuthenticator.user_password = {password!r}
c.Authenticator.allowed_users = {set(STUDENTS)!r}
c.JupyterHub.hub_port = {free_port()}
c.ConfigurableHTTPProxy.api_url = "http://127.0.0.1:{free_port()}"
c.JupyterHub.services = [{{"name": "classroom-test", "api_token": {token!r}}}]
c.JupyterHub.load_roles = [{{"name": "classroom-test", "services": ["classroom-test"],
    "scopes": ["admin:users", "admin:servers", "access:servers"]}}]
""")
    env = {key: value for key, value in os.environ.items()
           if not key.startswith(("ROS_", "_ROS_", "JUPYTER", "COURSE_"))}
    env.update(ROS2_COURSE_HOME=str(REPO), ROS2_COURSE_VENV=str(venv),
               ROS2_COURSE_STUDENTS=str(state / "no-students-file"), ROS2_COURSE_HUB_STATE=str(state),
               ROS2_COURSE_HUB_URL=f"http://127.0.0.1:{port}", ROS2_COURSE_PROXY=proxy)
    log_path = state / "jupyterhub.log"
    running = Hub(f"http://127.0.0.1:{port}", token, log_path)
    try:
        # on SIGTERM afterwards the hub stops what is left (cleanup_servers)
        with jupyterhub([sys.executable, "-m", "jupyterhub", "-f", str(test_config)], running.base,
                        log_path, cwd=state, env=env, timeout=60):
            try:
                running.password = password
                yield running
            finally:
                for name in STUDENTS:
                    try:
                        if running.server(name) is not None:
                            running.api("DELETE", f"/users/{name}/server")
                    except (AssertionError, requests.RequestException):
                        pass
    finally:
        for name in STUDENTS:
            _remove_user(name)
        shutil.rmtree(workdir, ignore_errors=True)


def KernelClient(hub: Hub, user: str, kernel_id: str) -> KernelChannels:
    """A student's kernel behind the hub's proxy (:class:`tests.servers.KernelChannels`)."""
    url = f"{hub.base.replace('http', 'ws', 1)}/user/{user}/api/kernels/{kernel_id}/channels"
    return KernelChannels(url, hub.token, user=user, timeout=CELL_TIMEOUT_S)


def _open_notebook(hub: Hub, user: str) -> tuple[KernelChannels, list[str]]:
    """A kernel for the student's own 00_welcome.ipynb (a session, as JupyterLab opens it), and its
    code cells read through the server's contents API."""
    base = f"{hub.base}/user/{user}/api"
    model = hub.http.get(f"{base}/contents/{NOTEBOOK}", timeout=30).json()
    assert model["type"] == "notebook", model
    response = hub.http.post(f"{base}/sessions", timeout=60, json={
        "path": NOTEBOOK, "name": NOTEBOOK, "type": "notebook", "kernel": {"name": "python3"}})
    assert response.status_code == 201, response.text
    cells = ["".join(c["source"]) if isinstance(c["source"], list) else c["source"]
             for c in model["content"]["cells"] if c["cell_type"] == "code"]
    return KernelClient(hub, user, response.json()["kernel"]["id"]), cells


def _through_runtime(cells: list[str]) -> list[str]:
    """The notebook's code cells up to and including the one that takes the kernel's runtime."""
    assert len(cells) > 10, cells
    taking = [i for i, code in enumerate(cells) if "get_runtime()" in code]
    assert taking, "notebook 00 no longer calls get_runtime()"
    return cells[:taking[0] + 1]


def _outside_view(domain: int, expect: list[str], workdir: Path) -> list[str]:
    """The nodes a fresh root process sees in ``domain``.

    It talks UDP only: over shared memory, Fast DDS participants of different Unix users do not
    discover each other (a student's process cannot write to root's segment in /dev/shm), so a
    probe with the default transports would see nothing whatever the domains.
    """
    env = {key: value for key, value in os.environ.items() if not key.startswith(("ROS_", "_ROS_"))}
    env.update(udp_loopback_env(str(workdir)))
    code = ("import json, sys; from course_helpers.core.domains import nodes_in_domain; "
            "print(json.dumps(nodes_in_domain(int(sys.argv[1]), wait_s=6.0, expect=sys.argv[2:])))")
    done = subprocess.run([sys.executable, "-c", code, str(domain), *expect], env=env, cwd=REPO,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


PROBE = """
import json, os, sys
import course_helpers
from course_helpers.nodes import Talker
from rclpy.node import Node
own = rt.add(Node, 'kernel_{user}')
child = rt.spawn('probe_{user}', Talker, params={{'name': 'probe_{user}'}}, wait_for='/probe_{user}')
print(json.dumps({{'domain': rt.domain.domain_id, 'kernel_pid': os.getpid(), 'child_pid': child.pid,
                  'uid': os.getuid(), 'cwd': os.getcwd(), 'python': sys.executable,
                  'course_writable': os.access(os.path.dirname(course_helpers.__file__), os.W_OK)}}))
"""
GRAPH = """
import json, time
# A window, on purpose (the one exception in this file): no sentinel can cross from one domain to another,
# which is the isolation under test. What holds by construction is asserted above: every kernel has a
# domain of its own. These 3 s only give a leak (a shared domain, a stray peer) the chance to show.
time.sleep(3.0)
print(json.dumps(sorted(rt.graph_nodes())))
"""


@pytest.mark.timing  # notebook 00's cells judge rates in the kernels (passed on by KernelChannels)
@pytest.mark.runs_alone  # a hub, its proxy and three kernels with nodes would starve a measurement beside it
def test_three_students_on_one_hub(hub, tmp_path):
    # The test authenticator: the shared password logs a student in, a wrong one does not.
    login = requests.Session()
    xsrf = login.get(f"{hub.base}/hub/login", timeout=30).cookies.get("_xsrf")
    wrong = login.post(f"{hub.base}/hub/login", data={"username": STUDENTS[0], "password": "nope",
                                                      "_xsrf": xsrf}, allow_redirects=False, timeout=30)
    right = login.post(f"{hub.base}/hub/login", data={"username": STUDENTS[0], "password": hub.password,
                                                      "_xsrf": xsrf}, allow_redirects=False, timeout=30)
    assert wrong.status_code == 403 and right.status_code == 302, (wrong.status_code, right.status_code)

    # Each student's server, started through the hub's REST API.
    started = time.monotonic()
    for user in STUDENTS:
        hub.api("POST", f"/users/{user}/server")
    for user in STUDENTS:
        if not poll_until(lambda u=user: (hub.server(u) or {}).get("ready"), 150, period=0.5):
            pytest.fail(f"{user}'s server did not become ready:\n{hub.log_tail()}")

    figures = {"servers_ready_s": round(time.monotonic() - started, 1)}
    # Notebook 00 of each student's working copy. The three kernels open it and take their ROS domains
    # at the same time (the race the domain reservation must win); then each runs the rest of it in
    # turn, as the timing stage runs one measurement at a time: its cells judge rates on the wall clock.
    started = time.monotonic()
    with ThreadPoolExecutor(len(STUDENTS)) as pool:
        opened = dict(zip(STUDENTS, pool.map(lambda u: _open_notebook(hub, u), STUDENTS), strict=True))
        first = {user: _through_runtime(cells) for user, (_, cells) in opened.items()}

        def run_first(user: str) -> None:
            for code in first[user]:
                opened[user][0].run(code)

        list(pool.map(run_first, STUDENTS))
    clients, facts = {}, {}
    for user, (client, cells) in opened.items():
        for code in cells[len(first[user]):]:
            client.run(code)
        clients[user] = client
        facts[user] = json.loads(client.run(PROBE.format(user=user)).strip().splitlines()[-1])
    figures["notebook_00_in_three_kernels_s"] = round(time.monotonic() - started, 1)

    domains = {user: fact["domain"] for user, fact in facts.items()}
    assert len(set(domains.values())) == len(STUDENTS), f"kernels share a ROS domain: {domains}"
    for user, fact in facts.items():
        home = pwd.getpwnam(user)
        assert fact["uid"] == home.pw_uid, fact
        assert fact["cwd"] == os.path.join(home.pw_dir, "ros2-course-work"), fact
        assert not fact["course_writable"], f"{user} can write to the shared course: {fact}"
        assert (Path(home.pw_dir) / "ros2-course-work" / NOTEBOOK).stat().st_uid == home.pw_uid

    # Each kernel sees its own nodes and none of the others', from inside and from outside.
    with ThreadPoolExecutor(len(STUDENTS)) as pool:
        seen = dict(zip(STUDENTS, pool.map(lambda u: json.loads(clients[u].run(GRAPH).strip()), STUDENTS),
                        strict=True))
    for user in STUDENTS:
        own = {f"/kernel_{user}", f"/probe_{user}"}
        others = {f"/{kind}_{other}" for other in STUDENTS if other != user for kind in ("kernel", "probe")}
        outside = set(_outside_view(domains[user], sorted(own), tmp_path))
        for view, names in (("the kernel", set(seen[user])), ("a probe outside", outside)):
            assert own <= names, f"{view} of {user} (domain {domains[user]}) misses its nodes: {names}"
            assert not others & names, f"{view} of {user} sees another student's nodes: {names}"
    for client in clients.values():
        client.close()

    figures["memory_per_student_mb"] = {user: _memory_mb(pwd.getpwnam(user).pw_uid) for user in STUDENTS}
    os.makedirs(ARTIFACTS, exist_ok=True)
    with open(os.path.join(ARTIFACTS, "classroom_hub.json"), "w", encoding="utf-8") as out:
        json.dump(figures, out, indent=1)
    # Stopping a student's server leaves nothing of theirs running: no kernel, no ROS child.
    for user in STUDENTS:
        uid = pwd.getpwnam(user).pw_uid
        before = _pids_of(uid)
        assert {facts[user]["kernel_pid"], facts[user]["child_pid"]} <= set(before), _describe(before)
        hub.api("DELETE", f"/users/{user}/server")
        assert poll_until(lambda u=user: hub.server(u) is None, 60, period=0.5), hub.log_tail()
        left: list[int] = []

        def nothing_left(uid=uid, left=left) -> bool:
            left[:] = _pids_of(uid)
            return not left

        assert poll_until(nothing_left, 20), \
            f"{user}'s processes left after their server stopped: {_describe(left)}\n{hub.log_tail()}"
        assert domain_free(domains[user]) or domain_holders(domains[user]).isdisjoint(before), \
            f"domain {domains[user]} is still held by {user}'s processes"
    # ... because each server shut its kernel down (classroom/singleuser.py), not because the kernels
    # found themselves orphaned and quit without cleaning up.
    log = hub.log.read_text(errors="replace")
    assert log.count("Shutting down 1 kernel") >= len(STUDENTS), hub.log_tail()
    assert "Parent appears to have exited" not in log, hub.log_tail()
