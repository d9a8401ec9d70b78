"""A package's executables, found and run as ``ros2 run PACKAGE EXECUTABLE`` does.

:func:`find_executable` looks the package up in the ament index; :func:`start_process`
starts the executable as its own process through the course's process layer (group
``'package'``), and :func:`stop_process` stops it as Ctrl+C would.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

from course_helpers.core import processes
from course_helpers.core.errors import CourseError
from course_helpers.core.processes import ChildProcess
from course_helpers.core.spawning import CHILD_HANG_S

PROCESS_GROUP = "package"  # the process layer's group for `ros2 run`-style processes
STOP_GRACE_S = 3.0  # s; SIGINT, then SIGKILL after this long


def find_executable(package: str, executable: str, env: dict[str, str]) -> Path:
    """The path of ``lib/PACKAGE/EXECUTABLE``, found as ``ros2 run`` finds it: through the ament index.

    For each prefix on ``env['AMENT_PREFIX_PATH']``, a package exists if
    ``share/ament_index/resource_index/packages/PACKAGE`` exists there; its executables are
    the files in ``PREFIX/lib/PACKAGE/``. Raises CourseError naming what is missing.
    """
    prefixes = [p for p in env.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    for prefix in prefixes:
        marker = Path(prefix) / "share" / "ament_index" / "resource_index" / "packages" / package
        if not marker.is_file():
            continue
        candidate = Path(prefix) / "lib" / package / executable
        if candidate.is_file() and os.access(candidate, os.X_OK):
            return candidate
        found = sorted(p.name for p in (Path(prefix) / "lib" / package).glob("*")
                       if p.is_file() and os.access(p, os.X_OK))
        raise CourseError(
            f"No executable {executable!r} found in package {package!r}; it has: "
            f"{', '.join(found) or 'none'}. Executables come from the console_scripts "
            "entry points in setup.py, installed into lib/PACKAGE by setup.cfg's "
            "[install] install_scripts line.")
    raise CourseError(f"Package {package!r} not found (is it built, and is the workspace's "
                      "install/ on AMENT_PREFIX_PATH?)")


def start_process(label: str, command: list[str], env: dict[str, str], cwd: Path | str) -> ChildProcess:
    """Start ``command`` as the process ``label`` (an old one with that label is stopped first).

    ``env`` adds to this kernel's environment. The process dies with the kernel, and
    :func:`stop_process` stops it with SIGINT first, as Ctrl+C would stop ``ros2 run``.
    """
    return processes.start(label, processes.program_argv(*command), group=PROCESS_GROUP, env=env,
                           cwd=str(cwd), channel=False, stop_signal=signal.SIGINT)


def stop_process(label: str, grace_s: float = STOP_GRACE_S) -> int | None:
    """Stop the process ``label`` as Ctrl+C would (SIGINT), then SIGKILL after ``grace_s``;
    its exit code (None if no such process runs)."""
    return processes.stop([label], group=PROCESS_GROUP, grace_s=grace_s).get(label)


def running_processes() -> dict[str, ChildProcess]:
    """The processes started with :func:`start_process` (``Workspace.run``) and not stopped, by label."""
    return processes.running(PROCESS_GROUP)


def wait_for_process_node(child: ChildProcess, fqn: str, timeout: float = CHILD_HANG_S) -> None:
    """Wait until the node ``fqn`` shows up in this kernel's ROS graph; raise early if the process ends."""
    from course_helpers.core.runtime import get_runtime

    get_runtime().wait_for_child_node(child, fqn, timeout)
