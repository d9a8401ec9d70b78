"""The servers the tests start: JupyterLab, JupyterHub and the image's container, each started, waited
for and stopped in one way (the process plumbing is ``tools/servers.py``, which ``make lab`` uses too).

* :func:`jupyter_lab`: JupyterLab on a free port with a random token, the course's notebooks as its root,
  the test's own settings (``tests/browsers.py``), runtime files and checkpoints in a scratch folder;
  yields a :class:`Lab`; afterwards shuts every kernel down through the API, stops the server and
  fails the test if a kernel was left;
* :func:`jupyterhub`: a JupyterHub command, waited for until its API answers; stopped afterwards;
* :class:`KernelChannels`: code run in a kernel of a Jupyter server over its websocket, as JupyterLab
  runs a cell; a timing statement the kernel judges is passed on to this process's timing watchers, so
  that conftest's stage check sees time judged in a kernel as it sees time judged in the test;
* :class:`ContainerServer`: a detached container of the course's image serving HTTP.
"""

from __future__ import annotations

import ast
import contextlib
import json
import os
import secrets
import shutil
import sys
import tempfile
import urllib.error
import urllib.request
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from course_helpers.core import verdict
from course_helpers.core.waiting import poll_until
from tools.servers import ServerProcess, answers, api, free_port

from .browsers import write_lab_settings

REPO = Path(__file__).resolve().parent.parent
START_TIMEOUT_S = 90  # JupyterLab or a hub start in seconds; a busy 2-core machine may take a minute


def start_or_fail(server: ServerProcess, ready, timeout: float = START_TIMEOUT_S) -> None:
    """Wait until ``ready()``; fail the test with the end of the server's log if it ended or timed out."""
    if not server.wait_until(ready, timeout):
        state = f"ended with {server.returncode}" if server.ended() else f"did not answer in {timeout:.0f} s"
        pytest.fail(f"{server.what} {state}:\n{server.log_tail()}")


def shut_down_kernels(base: str, token: str) -> list | None:
    """Shut every kernel of the Jupyter server at ``base`` down; the kernels still listed after (None
    when the server no longer answers)."""
    try:
        for kernel in api(base, token, "/api/kernels") or []:
            api(base, token, f"/api/kernels/{kernel['id']}", method="DELETE", timeout=60)
        return api(base, token, "/api/kernels")
    except OSError:
        return None


@dataclass
class Lab:
    """A running JupyterLab: its base URL, token, process and scratch folder."""

    base: str
    token: str
    server: ServerProcess
    folder: Path

    def api(self, path: str, method: str = "GET", body: dict | None = None, timeout: float = 30):
        return api(self.base, self.token, path, method=method, body=body, timeout=timeout)

    def url(self, path: str) -> str:
        """``path`` ('lab/tree/00_welcome.ipynb') on this server, with the token."""
        return f"{self.base}/{path}?token={self.token}"

    def open_notebook(self, path: str, kernel: str = "python3") -> tuple[str, KernelChannels]:
        """A session for the notebook ``path`` (as JupyterLab opens one) with a new ``kernel``:
        (its kernel id, its channels)."""
        session = self.api("/api/sessions", method="POST", timeout=120,
                           body={"path": path, "name": os.path.basename(path), "type": "notebook",
                                 "kernel": {"name": kernel}})
        kernel_id = session["kernel"]["id"]
        url = f"{self.base.replace('http', 'ws', 1)}/api/kernels/{kernel_id}/channels"
        return kernel_id, KernelChannels(url, self.token)


@contextlib.contextmanager
def jupyter_lab(root: str | Path = REPO / "notebooks", env: dict[str, str] | None = None,
                options: tuple[str, ...] = (), kernel_transport: str = "ipc") -> Iterator[Lab]:
    """JupyterLab serving ``root`` for the block (see the module's docstring). ``env`` adds variables to
    the server's (and so its kernels') environment; ``options`` are more command-line options.

    Its kernels listen on Unix sockets in the runtime folder (``kernel_transport="ipc"``): no TCP port
    to race the other tests' kernels for (tools/kernels.py). A kernel run as another user cannot make
    sockets there; ``kernel_transport="tcp"`` is for that."""
    folder = Path(tempfile.mkdtemp(prefix="course-lab-test-"))
    settings = write_lab_settings(folder / "settings")
    port, token = free_port(), secrets.token_hex(16)
    environment = dict(os.environ)
    environment.pop("ROS_DOMAIN_ID", None)  # each kernel reserves a domain of its own
    environment.update(JUPYTER_CONFIG_DIR=str(folder / "config"), JUPYTER_RUNTIME_DIR=str(folder / "runtime"))
    environment.update(env or {})
    argv = [sys.executable, "-m", "jupyter", "lab", "--no-browser", f"--port={port}",
            "--ServerApp.ip=127.0.0.1", f"--ServerApp.token={token}", f"--ServerApp.root_dir={root}",
            f"--LabApp.user_settings_dir={settings}", f"--LabApp.workspaces_dir={folder / 'workspaces'}",
            f"--FileCheckpoints.root_dir={folder / 'checkpoints'}",  # not beside the course's notebooks
            "--LabApp.extension_manager=readonly", "--LabApp.news_url=None",
            "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate",
            f"--KernelManager.transport={kernel_transport}",
            *(["--allow-root"] if os.geteuid() == 0 else []), *options]
    server = ServerProcess(argv, folder / "jupyter.log", cwd=REPO, env=environment, what="JupyterLab")
    lab = Lab(f"http://127.0.0.1:{port}", token, server, folder)
    remaining = None
    try:
        start_or_fail(server, lambda: answers(lab.base, token))
        yield lab
    finally:
        remaining = shut_down_kernels(lab.base, token)
        server.stop()
        shutil.rmtree(folder, ignore_errors=True)
    assert not remaining, f"kernels left running: {remaining}"


@contextlib.contextmanager
def jupyterhub(argv: list[str], base: str, log_path: str | Path, cwd: str | Path, env: dict[str, str],
               timeout: float = START_TIMEOUT_S) -> Iterator[ServerProcess]:
    """The hub ``argv`` for the block, once its API at ``base`` answers; SIGTERM afterwards (the hub
    stops the servers it still runs), SIGKILL after 30 s."""
    hub = ServerProcess(argv, log_path, cwd=cwd, env=env, what="JupyterHub")
    try:
        start_or_fail(hub, lambda: answers(base, None, "/hub/api/"), timeout)
        yield hub
    finally:
        hub.stop(timeout=30)


class KernelChannels:
    """Runs code in a kernel of a Jupyter server over the server's kernel websocket (the way JupyterLab
    does), and returns what it printed.

    Before the first run it asks the kernel, silently, to record each timing statement it judges
    (``course_helpers.core.verdict.TIMING_WATCHERS``); every run reads that record back as a user
    expression and tells this process's timing watchers of the statements not yet passed on. A kernel
    without the course's helpers records nothing.
    """

    RECORD = "_course_timing_judged"  # the kernel's list of the timing statements it judged
    WATCH = (f"{RECORD} = []\n"
             "try:\n"
             "    from course_helpers.core import verdict as _course_verdict\n"
             "except ImportError:\n"
             "    pass\n"
             "else:\n"
             f"    _course_verdict.TIMING_WATCHERS.append({RECORD}.append)\n"
             "    del _course_verdict\n")

    def __init__(self, url: str, token: str, user: str = "test", timeout: float = 120):
        import websocket  # websocket-client

        self.ws = websocket.create_connection(url, header=[f"Authorization: token {token}"], timeout=timeout)
        self.session, self.user = uuid.uuid4().hex, user
        self.watching, self.passed_on = False, 0

    def run(self, code: str) -> str:
        """Execute ``code``; return its stdout and results; fail the test with the traceback on error."""
        if not self.watching:
            self._execute(self.WATCH, silent=True, read_record=False)
            self.watching = True
        printed, reply = self._execute(code)
        failed = reply["status"] != "ok"
        # After an error the kernel reads no expressions: the record is asked for again, silently.
        self._pass_on_timing(self._execute("", silent=True)[1] if failed else reply)
        if failed:
            pytest.fail(f"{self.user}'s kernel: {reply.get('ename')}: {reply.get('evalue')}\n"
                        + "\n".join(reply.get("traceback", []))[-3000:] + f"\n\n{code[:300]}")
        return "".join(printed)

    def _execute(self, code: str, silent: bool = False, read_record: bool = True) -> tuple[list[str], dict]:
        """Send one execute request; (what it printed, its reply) once the kernel is idle again. With
        ``read_record`` the reply carries the kernel's record of judged timing statements."""
        msg_id = uuid.uuid4().hex
        expressions = {"judged": self.RECORD} if read_record else {}
        self.ws.send(json.dumps({
            "header": {"msg_id": msg_id, "session": self.session, "username": self.user,
                       "msg_type": "execute_request", "version": "5.3"},
            "parent_header": {}, "metadata": {}, "buffers": [], "channel": "shell",
            "content": {"code": code, "silent": silent, "store_history": not silent,
                        "user_expressions": expressions, "allow_stdin": False, "stop_on_error": True}}))
        printed, reply, idle = [], None, False
        while reply is None or not idle:
            frame = self.ws.recv()
            if isinstance(frame, bytes):
                continue  # binary frames carry widget buffers only
            message = json.loads(frame)
            if message.get("parent_header", {}).get("msg_id") != msg_id:
                continue
            kind, content = message["msg_type"], message["content"]
            if kind == "stream":
                printed.append(content["text"])
            elif kind in ("execute_result", "display_data"):
                printed.append(content["data"].get("text/plain", "") + "\n")  # a display is a line of its own
            elif kind == "status":
                idle = content["execution_state"] == "idle"
            elif kind == "execute_reply":
                reply = content
        if silent and reply["status"] != "ok":
            pytest.fail(f"{self.user}'s kernel refused the test's own set-up: {reply.get('evalue')}")
        return printed, reply

    def _pass_on_timing(self, reply: dict) -> None:
        """Tell this process's timing watchers of each statement the kernel judged since the last run."""
        judged = reply["user_expressions"]["judged"]
        if judged["status"] != "ok":
            pytest.fail(f"{self.user}'s kernel lost the test's record of judged timing statements "
                        f"({self.RECORD}): {judged.get('ename')}: {judged.get('evalue')}")
        statements = ast.literal_eval(judged["data"]["text/plain"])
        for statement in statements[self.passed_on:]:
            verdict.tell_timing_watchers(statement)
        self.passed_on = len(statements)

    def close(self) -> None:
        self.ws.close()


def http_get(url: str, token: str | None = None) -> tuple[int, dict, str]:
    """(status, headers, body) of a GET without following redirects."""
    class NoRedirect(urllib.request.HTTPRedirectHandler):
        def redirect_request(self, *args, **kwargs):
            return None

    request = urllib.request.Request(url, headers={"Authorization": f"token {token}"} if token else {})
    try:
        with urllib.request.build_opener(NoRedirect).open(request, timeout=10) as response:
            return response.status, response.headers, response.read().decode()
    except urllib.error.HTTPError as error:
        return error.code, error.headers, error.read().decode(errors="replace")


class ContainerServer:
    """A detached container of ``image`` serving HTTP; stopped (and removed) by :meth:`stop`.

    ``options`` go to ``run`` before the image, ``{port}`` in them standing for a free port of the host.
    """

    def __init__(self, engine, image: str, options: list[str], *command: str):
        self.engine, self.port = engine, free_port()
        self.name = f"course-image-test-{secrets.token_hex(4)}"
        engine.call("run", "--detach", "--name", self.name, *[o.format(port=self.port) for o in options],
                    image, *command, check=True)

    def wait_for(self, url: str, timeout: float = 90) -> None:
        """Until ``url`` answers with a status below 500; fails the test with the container's log."""
        def serves() -> bool:
            try:
                return http_get(url)[0] < 500
            except OSError:
                return False
        if not poll_until(serves, timeout, period=0.5):
            pytest.fail(f"{url} did not answer within {timeout:.0f} s; the container's log:\n"
                        f"{self.logs()[-4000:]}")

    def logs(self) -> str:
        done = self.engine.call("logs", self.name)
        return done.stdout + done.stderr

    def stop(self) -> int:
        """Stop the container (SIGTERM, SIGKILL after 20 s), remove it; return its exit code."""
        self.engine.call("stop", "--time", "20", self.name, timeout=60)
        code = self.engine.call("inspect", "--format", "{{.State.ExitCode}}", self.name).stdout.strip()
        self.engine.call("rm", "--force", self.name)
        return int(code or -1)
