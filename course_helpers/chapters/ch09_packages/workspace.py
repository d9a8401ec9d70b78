"""A real colcon workspace in a temporary directory: :class:`Workspace`.

``ws = Workspace()`` creates ``src/`` in a new temporary directory; ``ws.create_package``
writes an ``ament_python`` package (what ``ros2 pkg create`` would write); ``ws.build()``
runs the real ``colcon build`` (``build/``, ``install/`` and ``log/`` appear beside
``src/``); ``ws.environment()`` is what ``source install/setup.bash`` would give;
``ws.run(package, executable)`` starts an executable as its own process, as ``ros2 run``
does. Nothing is left in the course's repository: ``ws.cleanup()`` (or the kernel's exit)
deletes the directory and stops the processes started from it.
"""

from __future__ import annotations

import atexit
import os
import re
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

from course_helpers.chapters.ch09_packages.colcon import (
    COLCON_TIMEOUT_S,
    ColconBuild,
    colcon_command,
    run_colcon,
)
from course_helpers.chapters.ch09_packages.environment import (
    forget_env_entries_under,
    installed_packages,
    stable_name,
    workspace_environment,
)
from course_helpers.chapters.ch09_packages.executables import (
    find_executable,
    start_process,
    stop_process,
    wait_for_process_node,
)
from course_helpers.chapters.ch09_packages.package_files import (
    ament_python_files,
    check_package_name,
    path_inside,
    write_package_files,
)
from course_helpers.chapters.ch09_packages.provisioned import Provisioned, provision
from course_helpers.core.errors import CourseError
from course_helpers.core.processes import ChildProcess
from course_helpers.core.spawning import CHILD_HANG_S

# Workspaces by label: creating a workspace with a label already in use removes the old one.
_workspaces: dict[str, Workspace] = {}


class Workspace:
    """A colcon workspace in a new temporary directory: ``src/`` now, the rest after a build.

    ``label`` names the workspace for re-run safety: creating another workspace with
    the same label deletes the old one (and stops the processes started from it).
    """

    def __init__(self, label: str = "ros2_ws"):
        if not isinstance(label, str) or not re.match(r"^[A-Za-z0-9_]+$", label):
            raise CourseError(f"label must be letters, digits and underscores, got {label!r}")
        old = _workspaces.pop(label, None)
        if old is not None:
            old.cleanup()
        self.label = label
        self.root = Path(tempfile.mkdtemp(prefix=f"{label}_"))
        self.src = self.root / "src"
        self.src.mkdir()
        self.build_base = self.root / "build"
        self.install_base = self.root / "install"
        self.log_base = self.root / "log"
        self.process_labels: list[str] = []
        _workspaces[label] = self

    def __repr__(self) -> str:
        return f"<Workspace {self.label!r} at {self.root}>"

    def __enter__(self) -> Workspace:
        return self

    def __exit__(self, *exc) -> None:
        self.cleanup()

    # ---------------------------------------------------------------- writing packages
    def create_package(self, name: str, node_name: str,
                       dependencies: tuple[str, ...] | list[str] = ("rclpy",),
                       description: str = "A package made in chapter 09",
                       node_source: str | None = None, executable: str | None = None) -> Path:
        """Write an ament_python package into ``src/NAME``, as ``ros2 pkg create --build-type
        ament_python --node-name NODE_NAME NAME --dependencies ...`` would.

        The node module ``NAME/NODE_NAME.py`` starts as a small template with a ``main()``
        (pass ``node_source`` to write your own); the console script ``executable``
        (default: ``node_name``) runs ``NAME.NODE_NAME:main``. Returns the package directory.
        """
        return self.write_package(name, ament_python_files(name, node_name, dependencies, description,
                                                           node_source, executable))

    def write_package(self, name: str, files: dict[str, str]) -> Path:
        """Write ``files`` (relative path -> text) into ``src/NAME``, replacing what was there;
        returns the package directory."""
        check_package_name(name)
        if not isinstance(files, dict) or not files:
            raise CourseError("files must be a dict of relative path -> file text, e.g. "
                              "{'package.xml': '...', 'setup.py': '...'}")
        package_dir = self.src / name
        if package_dir.exists():
            shutil.rmtree(package_dir)
        write_package_files(package_dir, files)
        return package_dir

    def read(self, relative: str) -> str:
        """The text of a file in the workspace, e.g. ``ws.read('src/pkg/setup.py')``."""
        return path_inside(self.root, relative).read_text()

    # ---------------------------------------------------------------- building
    def colcon_command(self, packages: list[str] | None = None) -> list[str]:
        """The ``colcon build`` command line this workspace runs (everything inside the workspace)."""
        return colcon_command(self.src, self.build_base, self.install_base, self.log_base, packages)

    def colcon_command_text(self, packages: list[str] | None = None) -> str:
        """The ``colcon build`` command as text, with the workspace directory shown as ``$WS``."""
        command = self.colcon_command(packages)
        command[0] = "colcon"
        return " ".join(command).replace(str(self.root), "$WS")

    def build(self, packages: list[str] | None = None, progress: Callable[[str], None] | None = None,
              timeout: float = COLCON_TIMEOUT_S) -> ColconBuild:
        """Run the real ``colcon build`` (of ``packages`` only, if given) to its end; what it did.

        ``progress`` gets each line colcon prints; in a notebook ``progress=build_progress()``
        shows a live indicator.
        """
        return run_colcon(self.colcon_command(packages), self.root, self.log_base, progress, timeout)

    # ---------------------------------------------------------------- the installed result
    def installed_packages(self) -> list[str]:
        """Packages in ``install/``, in the order colcon's setup script would add them."""
        return installed_packages(self.install_base)

    def environment(self, base: dict[str, str] | None = None) -> dict[str, str]:
        """The environment ``source install/setup.bash`` would give: a copy of ``base`` (default:
        this process's environment) with the hooks of every installed package applied."""
        return workspace_environment(self.install_base, base)

    def setup_changes(self) -> dict[str, list[str]]:
        """What sourcing the workspace adds: variable -> new entries, the workspace shown as ``$WS``."""
        before = dict(os.environ)
        after = self.environment(before)
        changes = {}
        for name in sorted(after):
            old = [p for p in before.get(name, "").split(os.pathsep) if p]
            new = [p for p in after[name].split(os.pathsep) if p and p not in old]
            if new:
                changes[name] = [stable_name(p.replace(str(self.root), "$WS")) for p in new]
        return changes

    def find_executable(self, package: str, executable: str, env: dict[str, str] | None = None) -> Path:
        """The path of ``lib/PACKAGE/EXECUTABLE``, found as ``ros2 run`` does: through the ament
        index of ``env`` (default: the workspace's environment)."""
        return find_executable(package, executable, self.environment() if env is None else env)

    def provision(self, package: str) -> Provisioned:
        """Set up, inside the workspace, a Python where only the ROS packages that ``src/PACKAGE``'s
        package.xml declares (and theirs) are installed, as ``rosdep install`` would set up a robot
        for it (:mod:`.provisioned`); pass the result to :meth:`run`."""
        return provision(package, self.src / package / "package.xml", self.install_base, self.environment(),
                         self.root / "provisioned_site")

    def run(self, package: str, executable: str, args: list[str] | tuple[str, ...] = (),
            label: str | None = None, wait_for: str | None = None,
            timeout: float = CHILD_HANG_S, provisioned: Provisioned | None = None) -> ChildProcess:
        """Start ``EXECUTABLE`` of ``PACKAGE`` as its own process, like ``ros2 run PACKAGE EXECUTABLE``.

        The process gets the workspace's environment (and this kernel's ROS domain), or, with
        ``provisioned`` (from :meth:`provision`), runs where only the ROS packages its package.xml
        declares are installed. A process with the same ``label`` (default: the executable's name)
        is stopped first. ``wait_for`` names a node (``'/battery_monitor'``) to wait for in the ROS
        graph. Returns the :class:`ChildProcess`.
        """
        env = self.environment()
        path = self.find_executable(package, executable, env)
        label = label or executable
        command = [str(path)] if provisioned is None else provisioned.command(path)
        child = start_process(label, [*command, *args], env if provisioned is None else provisioned.env,
                              self.root)
        if label not in self.process_labels:
            self.process_labels.append(label)
        if wait_for:
            wait_for_process_node(child, wait_for, timeout)
        return child

    # ---------------------------------------------------------------- viewing and cleaning
    def tree(self, relative: str = ".", max_depth: int = 4) -> str:
        """The workspace's files as a tree (log folders named by date are shown as one line)."""
        top = path_inside(self.root, relative)
        title = f"{self.label}/" if top == self.root else f"{top.relative_to(self.root)}/"
        return "\n".join([title, *_tree_lines(top, "", max_depth)])

    def cleanup(self) -> None:
        """Stop the processes started from this workspace and delete its directory."""
        for label in self.process_labels:
            stop_process(label)
        self.process_labels.clear()
        shutil.rmtree(self.root, ignore_errors=True)
        forget_env_entries_under(self.root)
        if _workspaces.get(self.label) is self:
            del _workspaces[self.label]


def _remove_workspaces() -> None:
    for workspace in list(_workspaces.values()):
        workspace.cleanup()


atexit.register(_remove_workspaces)  # the directories; the process layer stops the processes itself


def _tree_lines(directory: Path, indent: str, depth: int) -> list[str]:
    if depth <= 0:
        return []
    entries = sorted(directory.iterdir(), key=lambda p: (p.name.startswith("."), p.name))
    entries = [e for e in entries if e.name != "__pycache__"]
    dated = [e for e in entries if re.match(r"^build_\d{4}-", e.name)]
    entries = [e for e in entries if e not in dated]
    lines = [f"{indent}{'├── ' if entries else '└── '}build_<date>/  (one folder per build)"] if dated else []
    for index, entry in enumerate(entries):
        last = index == len(entries) - 1
        branch = "└── " if last else "├── "
        if entry.is_symlink():
            target = re.sub(r"^build_\d{4}-.*", "build_<date>", os.readlink(entry).split("/")[-1])
            lines.append(f"{indent}{branch}{entry.name} -> {target}")
        elif entry.is_dir():
            lines.append(f"{indent}{branch}{stable_name(entry.name)}/")
            lines += _tree_lines(entry, indent + ("    " if last else "│   "), depth - 1)
        else:
            lines.append(f"{indent}{branch}{stable_name(entry.name)}")
    return lines
