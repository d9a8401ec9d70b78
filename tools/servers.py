"""A local server program (JupyterLab, JupyterHub), started, waited for and stopped in one way.

``tools/lab.py`` (``make lab``) and the tests that serve the course (``tests/servers.py``) use it:

* :class:`ServerProcess` starts a program in a session of its own (so that a stop reaches whatever it
  started), its output in a log file; :meth:`~ServerProcess.wait_until` waits until it answers, or
  ends, or the time runs out; :meth:`~ServerProcess.stop` sends SIGTERM and, after a while, SIGKILL
  to its whole session;
* :func:`answers` and :func:`api` ask a Jupyter server's REST API with its token;
* :func:`free_port` is a free TCP port of this machine's loopback that no other program will be
  handed before the server binds it.
"""

from __future__ import annotations

import fcntl
import json
import os
import random
import signal
import socket
import subprocess
import tempfile
import urllib.error
import urllib.request
from collections.abc import Callable
from pathlib import Path

from course_helpers.core.waiting import poll_until

_held_ports: list = []  # the lock files of the ports this process was handed, held until it exits


def _ephemeral_ports() -> range:
    """The ports the kernel hands out for a bind to port 0 (Linux's ``ip_local_port_range``)."""
    try:
        low, high = map(int, Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split())
        return range(low, high + 1)
    except (OSError, ValueError):
        return range(32768, 61000)  # Linux's default


def free_port() -> int:
    """A TCP port that is free on 127.0.0.1 now, for a server that binds it a moment later.

    The usual way, binding port 0 and letting go, races: any program that binds port 0 in that moment
    (a Jupyter kernel does, five times) can be handed the same port. A CI run lost so the hub's proxy
    port to a kernel of another test worker. So the port comes from below the range that port 0 draws
    from, where nothing is handed out, and a lock file per port, held until this process ends, keeps
    the other test processes of this user from choosing it too.
    """
    ephemeral = _ephemeral_ports()
    candidates = [p for p in range(20000, 32768) if p not in ephemeral] or list(range(20000, 32768))
    locks = Path(tempfile.gettempdir()) / f"course-ports-{os.getuid()}"
    locks.mkdir(mode=0o700, exist_ok=True)
    if locks.stat().st_uid != os.getuid():
        raise RuntimeError(f"{locks} belongs to another user; remove it, or set TMPDIR to a folder of yours")
    for port in random.sample(candidates, min(len(candidates), 200)):
        handle = open(locks / str(port), "a")  # noqa: SIM115 - held open until this process ends
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            with socket.socket() as sock:
                sock.bind(("127.0.0.1", port))
        except OSError:  # another test process holds it, or something listens there
            handle.close()
            continue
        _held_ports.append(handle)
        return port
    raise RuntimeError(f"no free TCP port on 127.0.0.1 in {candidates[0]}-{candidates[-1]} (200 tried)")


def api(base: str, token: str | None, path: str, method: str = "GET", body: dict | None = None,
        timeout: float = 10):
    """``method`` ``base + path`` with ``token`` (a Jupyter server's or a hub's); the JSON answer or None.

    Raises ``urllib.error.HTTPError`` for an error status, ``OSError`` when nothing answers.
    """
    headers = {"Authorization": f"token {token}"} if token else {}
    data = None
    if body is not None:
        data, headers["Content-Type"] = json.dumps(body).encode(), "application/json"
    request = urllib.request.Request(f"{base}{path}", data=data, method=method, headers=headers)
    with urllib.request.urlopen(request, timeout=timeout) as response:
        answer = response.read()
    return json.loads(answer) if answer else None


def answers(base: str, token: str | None, path: str = "/api/status") -> bool:
    """Whether the server at ``base`` answers ``path`` with a success status."""
    try:
        api(base, token, path, timeout=5)
        return True
    except (OSError, ValueError):  # urllib.error.URLError and HTTPError are OSErrors
        return False


class ServerProcess:
    """A server program in a session of its own, its standard output and error in ``log_path``.

    ``argv``, ``cwd`` and ``env`` are :class:`subprocess.Popen`'s. Use it as a context manager, or call
    :meth:`stop` in a ``finally``.
    """

    def __init__(self, argv: list[str], log_path: str | Path, cwd: str | Path | None = None,
                 env: dict[str, str] | None = None, what: str = "the server"):
        self.what, self.log_path = what, Path(log_path)
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        self._log = open(self.log_path, "ab")  # closed by stop()
        self.process = subprocess.Popen(argv, cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=self._log,
                                        stderr=subprocess.STDOUT, start_new_session=True)

    @property
    def pid(self) -> int:
        return self.process.pid

    @property
    def returncode(self) -> int | None:
        return self.process.poll()

    def ended(self) -> bool:
        return self.process.poll() is not None

    def wait_until(self, ready: Callable[[], bool], timeout: float, period: float = 0.3) -> bool:
        """Wait until ``ready()`` (it answers): True; False when the program ended or ``timeout`` passed."""
        poll_until(lambda: self.ended() or ready(), timeout, period=period)
        return not self.ended() and ready()

    def log_tail(self, lines: int = 40) -> str:
        """The last ``lines`` lines of its log."""
        if not self._log.closed:
            self._log.flush()
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return "(no log)"

    def stop(self, timeout: float = 15, whole_session: bool = True) -> int | None:
        """SIGTERM to its session (or, with ``whole_session=False``, to the program alone, which then
        stops what it started itself: a Jupyter server shuts its kernels down); SIGKILL to the whole
        session after ``timeout`` s. Returns its exit status."""
        try:
            if self.process.poll() is None:
                try:
                    if whole_session:
                        os.killpg(self.process.pid, signal.SIGTERM)
                    else:
                        self.process.send_signal(signal.SIGTERM)
                    self.process.wait(timeout=timeout)
                except subprocess.TimeoutExpired:
                    os.killpg(self.process.pid, signal.SIGKILL)
                    self.process.wait(timeout=10)
                except ProcessLookupError:
                    pass
        finally:
            self._log.close()
        return self.process.returncode

    def __enter__(self) -> ServerProcess:
        return self

    def __exit__(self, *_exc) -> None:
        self.stop()
