"""``make lab``: open the course in JupyterLab, at its first notebook, and stop it cleanly with Ctrl-C.

What it does, in order:

1. brings the student's working copy up to date (``tools/working_copy.py``: new chapters are
   copied, changed cells merged, the student's edits kept);
2. starts JupyterLab on that copy with the **student configuration** (below), its log in
   ``WORK/.lab.log`` instead of the terminal;
3. waits until the server answers, reads its runtime file (the real port, which may differ from
   ``--port`` when that one is taken, and the token Jupyter made) and prints **one line**: the URL
   of the first notebook with its token, where the work is saved, and how to stop;
4. turns Ctrl-C (or SIGTERM, or a closed terminal) into a clean stop: the server shuts its kernels
   down, and every kernel stops its nodes and child processes.

The student configuration is one directory, ``tools/jupyterlab/student``, put first on
``JUPYTER_CONFIG_PATH``: its ``labconfig/page_config.json`` disables nbgrader's JupyterLab extension
(menu, "Create Assignment" panel, "Validate" button) and its ``jupyter_server_config.d/`` file the
four nbgrader server extensions (so nothing logs an nbgrader error either). Anything that starts
JupyterLab for a student (a container's entrypoint, a hub's spawner) needs only
``JUPYTER_CONFIG_PATH=<course>/tools/jupyterlab/student``.

``--instructor`` (``make lab INSTRUCTOR=1``) keeps nbgrader: the server serves the course's
repository and runs in ``assignments/``, nbgrader's course directory (docs/assignments.md), so the
formgrader finds the course inside the server's root.

Usage::

    python tools/lab.py [--work DIR] [--port 8888] [--ip 127.0.0.1] [--no-browser] [--instructor]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
from pathlib import Path

from tools import servers, working_copy

REPO = Path(__file__).resolve().parent.parent
STUDENT_CONFIG = REPO / "tools" / "jupyterlab" / "student"
START = "00_welcome.ipynb"  # the course's first notebook: where a student starts
LOG_NAME = ".lab.log"  # in the working copy (a hidden file: JupyterLab does not list it)
START_TIMEOUT_S = 120.0  # JupyterLab starts in a few seconds; a busy machine may take much longer
STOP_TIMEOUT_S = 30.0  # the server shuts its kernels down (each stops its nodes and children)


def student_environment(environ: dict[str, str]) -> dict[str, str]:
    """``environ`` with the student configuration first on ``JUPYTER_CONFIG_PATH``."""
    env = dict(environ)
    rest = [p for p in env.get("JUPYTER_CONFIG_PATH", "").split(os.pathsep) if p and p != str(STUDENT_CONFIG)]
    env["JUPYTER_CONFIG_PATH"] = os.pathsep.join([str(STUDENT_CONFIG), *rest])
    return env


def server_command(root: Path, port: int, ip: str, start_url: str, open_browser: bool) -> list[str]:
    """The JupyterLab command line: serve ``root`` on ``ip:port``, ``/`` and the browser at ``start_url``."""
    argv = [sys.executable, "-m", "jupyterlab", f"--ServerApp.root_dir={root}", f"--ServerApp.port={port}",
            f"--ServerApp.ip={ip}", f"--LabApp.default_url={start_url}",
            f"--ServerApp.open_browser={open_browser}"]
    if os.geteuid() == 0:  # containers and CI machines run as root; Jupyter wants to be told
        argv.append("--allow-root")
    return argv


def runtime_info(pid: int) -> dict | None:
    """What the server with ``pid`` wrote into its runtime file (url, port, token...), or None yet."""
    from jupyter_core.paths import jupyter_runtime_dir

    try:
        with open(Path(jupyter_runtime_dir()) / f"jpserver-{pid}.json", encoding="utf-8") as handle:
            return json.load(handle)
    except (OSError, ValueError):
        return None


def answers(info: dict) -> bool:
    """True when the server described by ``info`` answers its REST API."""
    return servers.answers(_local_base(info).rstrip("/"), info["token"])


def open_url(info: dict, path: str) -> str:
    """The URL to open ``path`` (e.g. 'lab/tree/00_welcome.ipynb') on this machine, with the token."""
    return f"{_local_base(info)}{path}?token={info['token']}"


def _local_base(info: dict) -> str:
    # A server that listens on every interface (a container) is still reached here as 127.0.0.1.
    return f"http://127.0.0.1:{info['port']}{info.get('base_url', '/')}"


class TerminalForeground:
    """While held, Ctrl-C in the terminal reaches this launcher alone.

    Under ``make``, the terminal sends SIGINT to make as well, which would end with
    ``make: *** [lab] Interrupt`` after a clean stop. The launcher takes a process group of its
    own and makes it the terminal's foreground, and gives the terminal back when it ends.
    Nothing happens when stdin is not a terminal or this process is not in the foreground.
    """

    def __init__(self):
        self._fd = self._previous = None

    def __enter__(self):
        try:
            fd = sys.stdin.fileno()
            if not os.isatty(fd) or os.tcgetpgrp(fd) != os.getpgrp():
                return self
            previous = os.tcgetpgrp(fd)
            os.setpgid(0, 0)
            self._set_foreground(fd, os.getpgrp())
            self._fd, self._previous = fd, previous
        except (OSError, ValueError, AttributeError):
            pass
        return self

    def __exit__(self, *_exc):
        if self._fd is not None:
            try:
                self._set_foreground(self._fd, self._previous)
            except OSError:
                pass  # the old group is gone; the shell takes the terminal back itself

    @staticmethod
    def _set_foreground(fd: int, group: int) -> None:
        old = signal.signal(signal.SIGTTOU, signal.SIG_IGN)  # a background group may not set it
        try:
            os.tcsetpgrp(fd, group)
        finally:
            signal.signal(signal.SIGTTOU, old)


class _Stop(Exception):
    """A stop signal arrived (Ctrl-C, SIGTERM, SIGHUP)."""


def _raise_stop(signum, _frame):
    raise _Stop(signal.Signals(signum).name)


def stop_server(server: servers.ServerProcess) -> int:
    """Stop the server as its own SIGTERM handler does (kernels first); its whole session is killed
    after STOP_TIMEOUT_S (the server and what it left behind)."""
    return server.stop(STOP_TIMEOUT_S, whole_session=False)


def _sync(work: Path) -> None:
    """Bring the working copy up to date and say so in a line or two (conflicts in full)."""
    said: list[str] = []
    try:
        results = working_copy.sync(work=work, echo=said.append)
    except (OSError, ValueError, SystemExit) as exc:  # never keep a student from their notebooks
        print(f"Your working copy was not updated: {exc}", file=sys.stderr)
        return
    outcomes = list(results.values())
    counts = {word: sum(o == word for o in outcomes) for word in ("copied", "updated")}
    others = [line for line in said[:-1] if not line.endswith((": copied", ": updated"))]
    news = ", ".join(f"{n} {word}" for word, n in counts.items() if n)
    print(f"Your working copy {work} is up to date with the course" + (f" ({news})." if news else "."))
    for line in others:  # merges with conflicts, files kept as the student left them
        print(f"  {line}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", default=None,
                        help=f"the working copy (default: ${working_copy.WORK_ENV}, "
                             f"else {working_copy.DEFAULT_WORK})")
    parser.add_argument("--port", type=int, default=8888, help="the port to try first (default 8888)")
    parser.add_argument("--ip", default="127.0.0.1",
                        help="the address to listen on (default 127.0.0.1; 0.0.0.0 in a container)")
    parser.add_argument("--no-browser", action="store_true", help="do not open a web browser")
    parser.add_argument("--instructor", action="store_true",
                        help="keep nbgrader's menu and formgrader; serve the course repository")
    args = parser.parse_args(argv)

    work = working_copy.work_dir(args.work)
    if args.instructor:
        root, cwd, env = REPO, REPO / "assignments", dict(os.environ)
        start, log_path = "lab", REPO / "build" / "lab-instructor.log"
    else:
        _sync(work)
        root, cwd, env = work, work, student_environment(os.environ)
        start, log_path = f"lab/tree/{START}", work / LOG_NAME
    log_path.parent.mkdir(parents=True, exist_ok=True)
    command = server_command(root, args.port, args.ip, "/" + start, not args.no_browser)

    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, _raise_stop)
    with TerminalForeground():
        server = None
        try:
            # A session of its own: the terminal's Ctrl-C reaches only this launcher, which stops
            # the server without JupyterLab's "Shut down this Jupyter server (y/[n])?" prompt.
            server = servers.ServerProcess(command, log_path, cwd=cwd, env=env, what="JupyterLab")
            info: dict = {}

            def ready() -> bool:
                info.update(runtime_info(server.pid) or {})
                return bool(info) and answers(info)

            if not server.wait_until(ready, START_TIMEOUT_S, period=0.2):
                server.stop(STOP_TIMEOUT_S, whole_session=False)
                print(f"JupyterLab did not start. The end of its log ({log_path}):\n{server.log_tail(25)}",
                      file=sys.stderr)
                return 1
            where = f"your work is saved in {work}" if not args.instructor else f"serving {root}"
            print(f"Open {open_url(info, start)} in your browser ({where}). "
                  "Press Ctrl-C here to stop JupyterLab and shut its kernels down.", flush=True)
            server.process.wait()
            code = server.stop()
            print(f"JupyterLab stopped on its own (exit code {code}); its log is {log_path}.",
                  file=sys.stderr)
            return code or 1
        except (_Stop, KeyboardInterrupt):
            for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
                signal.signal(signum, signal.SIG_IGN)  # a second Ctrl-C must not cut the clean stop short
            if server is None:
                return 0
            print("\nStopping JupyterLab: shutting its kernels down ...", flush=True)
            code = stop_server(server)
            print("JupyterLab stopped." if code == 0 else
                  f"JupyterLab stopped (exit code {code}; log {log_path}).")
            return 0


if __name__ == "__main__":
    sys.exit(main())
