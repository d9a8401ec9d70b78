"""A real colcon workspace in a temporary directory, and new interface packages (chapter 09).

Chapter 09 turns notebook nodes into ROS 2 packages and runs them the way a
robot does, without leaving anything in the course's repository:

* :class:`Workspace` creates ``src/`` in a temporary directory, writes an
  ``ament_python`` package (what ``ros2 pkg create`` would write), builds it
  with the real ``colcon build`` (``build/``, ``install/`` and ``log/`` appear
  beside ``src/``), computes the environment that ``source install/setup.bash``
  would give by reading the ``.dsv`` hook files colcon installed, finds an
  executable the way ``ros2 run`` does (through the ament index) and starts it
  as its own process;
* :func:`create_interface_package` writes a new interface package (``.msg``,
  ``.srv``, ``.action``), :func:`build_interface_package` builds it with rosidl
  into a temporary prefix, and :func:`load_interfaces` imports the generated
  classes into the running kernel; :func:`make_message_publisher` is a child
  process target that publishes such a new message from another process.

Everything lives under the system's temporary directory and is deleted by
:meth:`Workspace.cleanup` (or when the kernel exits).
"""

from __future__ import annotations

import atexit
import ctypes
import hashlib
import importlib
import os
import re
import shutil
import signal
import sys
import tempfile
import textwrap
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from course_helpers.core import processes
from course_helpers.core.errors import CourseError
from course_helpers.core.processes import ChildProcess

PACKAGE_NAME_RE = re.compile(r"^[a-z][a-z0-9_]*$")  # REP 144: lower case, digits, underscores
INTERFACE_NAME_RE = re.compile(r"^[A-Z][A-Za-z0-9]*$")
STOP_GRACE_S = 3.0
COLCON_TIMEOUT_S = 300.0

# Workspaces by label: creating a workspace with a label already in use removes the old one.
_workspaces: dict[str, Workspace] = {}
# Interface packages imported into this process: name -> digest of their definitions.
_loaded_interfaces: dict[str, str] = {}

# What `ros2 pkg create --node-name` puts in the node's module before you edit it.
_NODE_TEMPLATE = """\
def main():
    print('Hi from {package}.')


if __name__ == '__main__':
    main()
"""


# ---------------------------------------------------------------------------------- results
@dataclass
class ColconBuild:
    """What one ``colcon build`` did: exit code, packages and the type colcon gave each."""

    returncode: int
    seconds: float
    package_types: dict[str, str]
    finished: list[str]
    failed: list[str]
    output: str
    log_dir: Path

    @property
    def ok(self) -> bool:
        """True when colcon exited with 0."""
        return self.returncode == 0

    def summary(self) -> str:
        """A stable one-line-per-package summary (no timings)."""
        lines = [f"colcon build {'succeeded' if self.ok else 'FAILED'}"]
        for name in sorted(self.package_types):
            state = "finished" if name in self.finished else (
                "failed" if name in self.failed else "not built")
            lines.append(f"  {name:<22} {self.package_types[name]:<18} {state}")
        return "\n".join(lines)

    def log_tail(self, lines: int = 25) -> str:
        """The last lines colcon printed, plus the failed packages' own error output."""
        text = self.output.splitlines()[-lines:]
        for name in self.failed:
            stderr = self.log_dir / "latest_build" / name / "stdout_stderr.log"
            if stderr.is_file():
                text += [f"--- {name} output ---"]
                text += stderr.read_text(errors="replace").splitlines()[-lines:]
        return "\n".join(text)


# ---------------------------------------------------------------------------------- workspace
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
        """Write an ament_python package, as ``ros2 pkg create --build-type ament_python
        --node-name NODE_NAME NAME --dependencies ...`` would.

        The node module ``NAME/NODE_NAME.py`` starts as a small template with a ``main()``
        (pass ``node_source`` to write your own); the console script ``executable``
        (default: ``node_name``) runs ``NAME.NODE_NAME:main``. Returns the package directory.
        """
        _check_package_name(name)
        if not isinstance(node_name, str) or not node_name.isidentifier():
            raise CourseError(f"node_name must be a Python module name like 'battery_monitor', "
                              f"got {node_name!r}")
        if node_source is not None and (not isinstance(node_source, str) or "def main" not in node_source):
            raise CourseError("node_source must be the module's Python source, with a main() "
                              "function that the console script calls")
        executable = executable or node_name
        deps = list(dependencies)
        files = {
            "package.xml": package_xml(name, description, deps),
            "setup.py": setup_py(name, description, {executable: f"{name}.{node_name}:main"}),
            "setup.cfg": setup_cfg(name),
            f"resource/{name}": "",
            f"{name}/__init__.py": "",
            f"{name}/{node_name}.py": textwrap.dedent(node_source or _NODE_TEMPLATE.format(
                package=name)).lstrip("\n"),
        }
        return self.write_package(name, files)

    def write_package(self, name: str, files: dict[str, str]) -> Path:
        """Write ``files`` (relative path -> text) into ``src/NAME``, replacing what was there."""
        _check_package_name(name)
        if not isinstance(files, dict) or not files:
            raise CourseError("files must be a dict of relative path -> file text, e.g. "
                              "{'package.xml': '...', 'setup.py': '...'}")
        package_dir = self.src / name
        if package_dir.exists():
            shutil.rmtree(package_dir)
        for relative, text in files.items():
            path = _inside(package_dir, relative)
            if not isinstance(text, str):
                raise CourseError(f"the content of {relative!r} must be a string, got "
                                  f"{type(text).__name__}")
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
        return package_dir

    def read(self, relative: str) -> str:
        """The text of a file in the workspace, e.g. ``ws.read('src/pkg/setup.py')``."""
        return _inside(self.root, relative).read_text()

    # ---------------------------------------------------------------- building
    def colcon_command(self, packages: list[str] | None = None) -> list[str]:
        """The ``colcon build`` command line this workspace runs (everything inside the workspace)."""
        colcon = shutil.which("colcon", path=str(Path(sys.executable).parent)) or "colcon"
        command = [colcon, "--log-base", str(self.log_base), "build",
                   "--base-paths", str(self.src),
                   "--build-base", str(self.build_base),
                   "--install-base", str(self.install_base),
                   "--event-handlers", "console_stderr-"]
        if packages:
            command += ["--packages-select", *packages]
        return command

    def colcon_command_text(self, packages: list[str] | None = None) -> str:
        """The ``colcon build`` command as text, with the workspace directory shown as ``$WS``."""
        command = self.colcon_command(packages)
        command[0] = "colcon"
        return " ".join(command).replace(str(self.root), "$WS")

    def build(self, packages: list[str] | None = None, progress: Callable[[str], None] | None = None,
              timeout: float = COLCON_TIMEOUT_S) -> ColconBuild:
        """Run the real ``colcon build`` in a child process; ``progress`` gets each line it prints.

        In a notebook, ``progress=build_progress()`` shows a live indicator.
        """
        command = self.colcon_command(packages)
        env = {"PYTHONDONTWRITEBYTECODE": "1", "COLCON_HOME": None}
        started = time.monotonic()
        report = progress or (lambda _line: None)
        report("$ colcon build")
        returncode, output = processes.run(command, env=env, cwd=str(self.root), timeout=timeout,
                                           on_line=report)
        result = ColconBuild(
            returncode=returncode,
            seconds=time.monotonic() - started,
            package_types=_package_types(self.log_base / "latest_build" / "logger_all.log"),
            finished=re.findall(r"^Finished <<< (\S+)", output, re.MULTILINE),
            failed=re.findall(r"^Failed\s+<<< (\S+)", output, re.MULTILINE),
            output=output,
            log_dir=self.log_base,
        )
        report("done" if result.ok else "FAILED")
        return result

    # ---------------------------------------------------------------- the installed result
    def installed_packages(self) -> list[str]:
        """Packages in ``install/``, in the order colcon's setup script would add them."""
        index = {}
        for marker in sorted(self.install_base.glob("*/share/colcon-core/packages/*")):
            deps = [d for d in marker.read_text().split(":") if d]
            index[marker.name] = deps
        ordered: list[str] = []

        def visit(name, seen=()):
            if name in ordered or name not in index or name in seen:
                return
            for dep in index[name]:
                visit(dep, (*seen, name))
            ordered.append(name)

        for name in sorted(index):
            visit(name)
        return ordered

    def environment(self, base: dict[str, str] | None = None) -> dict[str, str]:
        """The environment ``source install/setup.bash`` would give, computed from colcon's hooks.

        colcon installs, for each package, ``share/PKG/package.dsv`` listing hooks such as
        ``prepend-non-duplicate;PYTHONPATH;lib/python3.X/site-packages``; the shell scripts
        do exactly what these lines say. Here they are applied to a copy of ``base``
        (default: this process's environment) instead of a shell.
        """
        env = dict(os.environ if base is None else base)
        for package in self.installed_packages():
            prefix = self.install_base / package
            _apply_dsv(prefix / "share" / package / "package.dsv", prefix, env)
        return env

    def setup_changes(self) -> dict[str, list[str]]:
        """What sourcing the workspace adds, per variable, with the workspace shown as ``$WS``."""
        before = dict(os.environ)
        after = self.environment(before)
        changes = {}
        for name in sorted(after):
            old = [p for p in before.get(name, "").split(os.pathsep) if p]
            new = [p for p in after[name].split(os.pathsep) if p and p not in old]
            if new:
                changes[name] = [_stable_name(p.replace(str(self.root), "$WS")) for p in new]
        return changes

    def find_executable(self, package: str, executable: str, env: dict[str, str] | None = None) -> Path:
        """Find ``lib/PACKAGE/EXECUTABLE`` as ``ros2 run`` does: through the ament index.

        For each prefix on ``AMENT_PREFIX_PATH`` (of the workspace's environment), a package
        exists if ``share/ament_index/resource_index/packages/PACKAGE`` exists there; its
        executables are the files in ``PREFIX/lib/PACKAGE/``.
        """
        env = self.environment() if env is None else env
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

    def run(self, package: str, executable: str, args: list[str] | tuple[str, ...] = (),
            label: str | None = None, wait_for: str | None = None, timeout: float = 15.0) -> ChildProcess:
        """Start ``EXECUTABLE`` of ``PACKAGE`` as its own process, like ``ros2 run PACKAGE EXECUTABLE``.

        The process gets the workspace's environment (and this kernel's ROS domain). A
        process with the same ``label`` (default: the executable's name) is stopped first.
        ``wait_for`` names a node (``'/battery_monitor'``) to wait for in the ROS graph.
        """
        env = self.environment()
        path = self.find_executable(package, executable, env)
        label = label or executable
        child = start_process(label, [str(path), *args], env, self.root)
        if label not in self.process_labels:
            self.process_labels.append(label)
        if wait_for:
            wait_for_process_node(child, wait_for, timeout)
        return child

    # ---------------------------------------------------------------- viewing and cleaning
    def tree(self, relative: str = ".", max_depth: int = 4) -> str:
        """The workspace's files as a tree (log folders named by date are shown as one line)."""
        top = _inside(self.root, relative)
        title = f"{self.label}/" if top == self.root else f"{top.relative_to(self.root)}/"
        return "\n".join([title, *_tree_lines(top, "", max_depth)])

    def cleanup(self) -> None:
        """Stop the processes started from this workspace and delete its directory."""
        for label in self.process_labels:
            stop_process(label)
        self.process_labels.clear()
        shutil.rmtree(self.root, ignore_errors=True)
        _forget_env_entries_under(self.root)
        if _workspaces.get(self.label) is self:
            del _workspaces[self.label]


# ---------------------------------------------------------------------------------- package files
def package_xml(name: str, description: str, dependencies: list[str],
                maintainer: str = "Course Student", email: str = "student@example.com") -> str:
    """A format-3 package.xml for an ament_python package."""
    depends = "\n".join(f"  <exec_depend>{dep}</exec_depend>" for dep in dependencies)
    return textwrap.dedent(f"""\
        <?xml version="1.0"?>
        <?xml-model href="http://download.ros.org/schema/package_format3.xsd" schematypens="http://www.w3.org/2001/XMLSchema"?>
        <package format="3">
          <name>{name}</name>
          <version>0.1.0</version>
          <description>{description}</description>
          <maintainer email="{email}">{maintainer}</maintainer>
          <license>Apache-2.0</license>

        {{depends}}

          <export>
            <build_type>ament_python</build_type>
          </export>
        </package>
        """).replace("{depends}", depends)


def setup_py(name: str, description: str, console_scripts: dict[str, str]) -> str:
    """A setup.py that installs the package marker, package.xml and console scripts."""
    scripts = "\n".join(f"            '{exe} = {target}'," for exe, target in console_scripts.items())
    return textwrap.dedent(f"""\
        from setuptools import setup

        package_name = '{name}'

        setup(
            name=package_name,
            version='0.1.0',
            packages=[package_name],
            data_files=[
                # the marker that lets ament (and `ros2 run`) find the package
                ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
                ('share/' + package_name, ['package.xml']),
            ],
            install_requires=['setuptools'],
            zip_safe=True,
            maintainer='Course Student',
            maintainer_email='student@example.com',
            description='{description}',
            license='Apache-2.0',
            entry_points={{
                'console_scripts': [
        {{scripts}}
                ],
            }},
        )
        """).replace("{scripts}", scripts)


def setup_cfg(name: str) -> str:
    """setup.cfg: put console scripts in lib/NAME, where ``ros2 run`` looks for executables."""
    return (f"[develop]\nscript_dir=$base/lib/{name}\n"
            f"[install]\ninstall_scripts=$base/lib/{name}\n")


def read_manifest(path: Path) -> dict:
    """The name, build type and dependencies of a package.xml (CourseError if it does not parse)."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise CourseError(f"{path.name} is not valid XML: {exc}") from None
    depends = sorted({e.text.strip() for tag in ("depend", "exec_depend", "build_depend")
                      for e in root.iter(tag) if e.text})
    return {
        "name": (root.findtext("name") or "").strip(),
        "build_type": (root.findtext("export/build_type") or "").strip(),
        "depends": depends,
    }


# ---------------------------------------------------------------------------------- processes
PROCESS_GROUP = "package"  # the process layer's group for `ros2 run`-style processes


def start_process(label: str, command: list[str], env: dict[str, str], cwd: Path | str) -> ChildProcess:
    """Start ``command`` as its own process that dies with the kernel; replaces ``label``.

    It is stopped with SIGINT first, as Ctrl+C would stop ``ros2 run`` in a terminal.
    """
    return processes.start(label, processes.program_argv(*command), group=PROCESS_GROUP, env=env,
                           cwd=str(cwd), channel=False, stop_signal=signal.SIGINT)


def stop_process(label: str, grace_s: float = STOP_GRACE_S) -> int | None:
    """Stop a started process as Ctrl+C would (SIGINT), then SIGKILL after ``grace_s``."""
    return processes.stop([label], group=PROCESS_GROUP, grace_s=grace_s).get(label)


def running_processes() -> dict[str, ChildProcess]:
    """The processes started with :meth:`Workspace.run`, by label."""
    return processes.running(PROCESS_GROUP)


def wait_for_process_node(child: ChildProcess, fqn: str, timeout: float = 15.0) -> None:
    """Wait until ``fqn`` shows up in this kernel's ROS graph; fail early if the process ends."""
    from course_helpers.core.runtime import get_runtime

    get_runtime().wait_for_child_node(child, fqn, timeout)


def _remove_workspaces() -> None:
    for workspace in list(_workspaces.values()):
        workspace.cleanup()


atexit.register(_remove_workspaces)


# ---------------------------------------------------------------------------------- progress
def build_progress(title: str = "colcon build"):
    """A live indicator for :meth:`Workspace.build` / :func:`build_interface_package`.

    In a notebook: a small widget with a spinner bar, the elapsed time and the latest
    line. Elsewhere: None (no output). Pass it as ``progress=``.
    """
    from course_helpers.core.console import in_jupyter_kernel

    if not in_jupyter_kernel():
        return None
    import ipywidgets as widgets
    from IPython.display import display

    bar = widgets.FloatProgress(value=0, min=0, max=1, bar_style="info",
                                layout=widgets.Layout(width="260px"))
    label = widgets.Label(value=f"{title}: starting")

    class ProgressBox(widgets.HBox):
        def __repr__(self) -> str:  # plain-text form: fixed, so notebook outputs stay comparable
            return f"<{title} progress>"

    display(ProgressBox([bar, label]))
    started = time.monotonic()

    def update(line: str) -> None:
        elapsed = time.monotonic() - started
        bar.value = min(0.95, elapsed / (elapsed + 5.0))  # creeps towards the end, never claims done
        if line in ("done", "FAILED"):
            bar.value = 1.0
            bar.bar_style = "success" if line == "done" else "danger"
        shown = line if len(line) < 90 else line[:87] + "..."
        label.value = f"{title} ({elapsed:.0f} s): {shown}"

    return update


# ---------------------------------------------------------------------------------- interfaces
def create_interface_package(parent_dir: str | os.PathLike, name: str,
                             messages: dict[str, str] | None = None,
                             services: dict[str, str] | None = None,
                             actions: dict[str, str] | None = None,
                             dependencies: tuple[str, ...] | list[str] = ()) -> Path:
    """Write an interface package (package.xml, CMakeLists.txt, msg/ srv/ action/) under ``parent_dir``.

    ``messages={'BinLevel': 'string bin_id\\nfloat32 fill_ratio'}`` writes ``msg/BinLevel.msg``.
    ``dependencies`` are other interface packages the definitions use (e.g. 'geometry_msgs').
    """
    _check_package_name(name)
    kinds = {"msg": messages or {}, "srv": services or {}, "action": actions or {}}
    if not any(kinds.values()):
        raise CourseError("give at least one definition: messages={'Name': 'int32 field'}")
    package_dir = Path(parent_dir) / name
    if package_dir.exists():
        shutil.rmtree(package_dir)
    listed = []
    for kind, definitions in kinds.items():
        for interface, text in sorted(definitions.items()):
            if not INTERFACE_NAME_RE.match(interface):
                raise CourseError(f"interface names are CamelCase like 'BinLevel', got {interface!r}")
            path = package_dir / kind / f"{interface}.{kind}"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(textwrap.dedent(text).strip() + "\n")
            listed.append(f"{kind}/{interface}.{kind}")
    deps = list(dependencies)
    find = "".join(f"find_package({dep} REQUIRED)\n" for dep in deps)
    files = "\n".join(f'  "{item}"' for item in listed)
    dep_line = f"\n  DEPENDENCIES {' '.join(deps)}" if deps else ""
    (package_dir / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.16)\n"
        f"project({name})\n\n"
        "find_package(ament_cmake REQUIRED)\n"
        "find_package(rosidl_default_generators REQUIRED)\n"
        f"{find}\n"
        "rosidl_generate_interfaces(${PROJECT_NAME}\n"
        f"{files}{dep_line}\n)\n\n"
        "ament_export_dependencies(rosidl_default_runtime)\n"
        "ament_package()\n")
    depend_lines = "".join(f"  <depend>{dep}</depend>\n" for dep in deps)
    (package_dir / "package.xml").write_text(
        '<?xml version="1.0"?>\n<package format="3">\n'
        f"  <name>{name}</name>\n  <version>0.1.0</version>\n"
        f"  <description>Interfaces made in chapter 09</description>\n"
        '  <maintainer email="student@example.com">Course Student</maintainer>\n'
        "  <license>Apache-2.0</license>\n\n"
        "  <buildtool_depend>ament_cmake</buildtool_depend>\n"
        "  <buildtool_depend>rosidl_default_generators</buildtool_depend>\n"
        f"{depend_lines}"
        "  <exec_depend>rosidl_default_runtime</exec_depend>\n"
        "  <member_of_group>rosidl_interface_packages</member_of_group>\n\n"
        "  <export>\n    <build_type>ament_cmake</build_type>\n  </export>\n</package>\n")
    return package_dir


def build_interface_package(source_dir: str | os.PathLike, install_prefix: str | os.PathLike,
                            progress: Callable[[str], None] | None = None):
    """Build an interface package with rosidl (CMake) into ``install_prefix``; return the BuildResult.

    ``colcon build`` would run the same CMake configure/build/install steps for a
    package whose build type is ament_cmake.
    """
    from course_helpers.core.build_interfaces import build_package

    prefix = Path(install_prefix)
    report = progress or (lambda _line: None)
    report("rosidl: generating and compiling")
    try:
        result = build_package(source_dir, prefix, build_dir=prefix.parent / "build_interfaces"
                               / Path(source_dir).name, progress=progress)
    except Exception:
        report("FAILED")
        raise
    report("done")
    return result


def interface_digest(source_dir: str | os.PathLike) -> str:
    """A digest of an interface package's definition files (to notice changed definitions)."""
    digest = hashlib.sha256()
    for path in sorted(Path(source_dir).rglob("*")):
        if path.suffix in (".msg", ".srv", ".action") and path.is_file():
            digest.update(path.name.encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


_LIBRARY_ORDER = ("generator_c", "typesupport_introspection_c", "typesupport_fastrtps_c",
                  "typesupport_c", "generator_py")


def load_interfaces(result, kind: str = "msg"):
    """Import a freshly built interface package into this (already running) process.

    A running process cannot learn a new library directory (``LD_LIBRARY_PATH`` is read
    at start-up), so the package's C libraries are loaded by path first, then the Python
    module is imported from the prefix. Returns ``PACKAGE.KIND`` (e.g. ``warehouse_msgs.msg``).
    A package that is already loaded with other definitions needs a kernel restart;
    new processes (``rt.spawn(..., env=interface_env(result))``) always get the new ones.
    """
    if kind not in ("msg", "srv", "action"):
        raise CourseError(f"kind must be 'msg', 'srv' or 'action', got {kind!r}")
    package = result.package
    digest = interface_digest(result.source_dir)
    loaded = _loaded_interfaces.get(package)
    if loaded is not None and loaded != digest:
        raise CourseError(
            f"{package} is already loaded in this kernel with other definitions; a running "
            "process cannot swap compiled libraries. Restart the kernel to use the new ones "
            "here (child processes started now already see them).")
    if loaded is None:
        if package in sys.modules:
            raise CourseError(f"a module called {package!r} is already imported; choose another "
                              "package name")
        lib = Path(result.library_dir)
        _prepend_env("LD_LIBRARY_PATH", str(lib))
        for suffix in _LIBRARY_ORDER:
            path = lib / f"lib{package}__rosidl_{suffix}.so"
            if path.is_file():
                ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL)
        python_dir = str(result.python_dir)
        if python_dir not in sys.path:
            sys.path.insert(0, python_dir)
        importlib.invalidate_caches()
        _loaded_interfaces[package] = digest
    _prepend_env("AMENT_PREFIX_PATH", str(result.install_prefix))  # `ros2 interface show` finds it
    return importlib.import_module(f"{package}.{kind}")


def _prepend_env(name: str, entry: str) -> None:
    current = [p for p in os.environ.get(name, "").split(os.pathsep) if p and p != entry]
    os.environ[name] = os.pathsep.join([entry, *current])


def _forget_env_entries_under(root: Path) -> None:
    """Drop the paths under a deleted workspace from this process's search paths."""
    for name in ("AMENT_PREFIX_PATH", "LD_LIBRARY_PATH"):
        kept = [p for p in os.environ.get(name, "").split(os.pathsep)
                if p and not p.startswith(str(root))]
        if kept:
            os.environ[name] = os.pathsep.join(kept)
        else:
            os.environ.pop(name, None)


def interface_env(result) -> dict[str, str]:
    """The variables a new process needs to import the package built by ``result``."""
    full = result.environment()
    keys = ("PYTHONPATH", "LD_LIBRARY_PATH", "AMENT_PREFIX_PATH", "_ROS_WHEELS_BOOTSTRAP_COMPLETE")
    return {k: full[k] for k in keys if k in full}


def make_message_publisher(type_name: str, topic: str, fields: dict | None = None,
                           rate_hz: float = 5.0, name: str = "message_publisher",
                           counter_field: str | None = None, namespace: str = ""):
    """Child-process target: publish ``type_name`` (any installed or freshly built message).

    ``fields`` set the message's fields; ``counter_field`` (an integer field) counts up.
    """
    from rclpy.node import Node

    from course_helpers.core.validation import resolve_interface

    msg_type = resolve_interface(type_name, "msg")
    node = Node(name, namespace=namespace)
    publisher = node.create_publisher(msg_type, topic, 10)
    state = {"count": 0}

    def tick():
        msg = msg_type(**(fields or {}))
        if counter_field:
            setattr(msg, counter_field, state["count"])
        publisher.publish(msg)
        state["count"] += 1

    node.publish_timer = node.create_timer(1.0 / rate_hz, tick)  # period in seconds
    return node


# ---------------------------------------------------------------------------------- internals
def _check_package_name(name: str) -> str:
    if not isinstance(name, str) or not PACKAGE_NAME_RE.match(name):
        raise CourseError(f"package names are lower case letters, digits and underscores, "
                          f"starting with a letter (REP 144), e.g. 'warehouse_tools'; got {name!r}")
    return name


def _inside(base: Path, relative: str) -> Path:
    if not isinstance(relative, str) or not relative or Path(relative).is_absolute():
        raise CourseError(f"paths must be relative, like 'setup.py' or 'pkg/node.py'; got {relative!r}")
    path = (base / relative).resolve()
    if path != base.resolve() and base.resolve() not in path.parents:
        raise CourseError(f"path {relative!r} leaves the package directory")
    return path


def _package_types(logger_all: Path) -> dict[str, str]:
    """Package name -> type that colcon identified ('ros.ament_python', 'python', ...)."""
    try:
        text = logger_all.read_text(errors="replace")
    except OSError:
        return {}
    found = re.findall(r"Package '[^']*' with type '([^']+)' and name '([^']+)'", text)
    return {name: kind for kind, name in found}


def _apply_dsv(path: Path, prefix: Path, env: dict[str, str]) -> None:
    """Apply one colcon .dsv hook file to ``env`` (the lines the shell scripts implement)."""
    if not path.is_file():
        return
    for line in path.read_text().splitlines():
        kind, _, rest = line.partition(";")
        if kind == "source":
            if rest.endswith(".dsv"):
                _apply_dsv(prefix / rest, prefix, env)
            continue  # the .sh/.bash twins of a .dsv do the same thing for a shell
        name, _, values = rest.partition(";")
        entries = [str(prefix / v) if v else str(prefix) for v in values.split(";")]
        current = [p for p in env.get(name, "").split(os.pathsep) if p]
        if kind in ("prepend-non-duplicate", "prepend-non-duplicate-if-exists"):
            if kind.endswith("if-exists"):
                entries = [e for e in entries if os.path.exists(e)]
            env[name] = os.pathsep.join([*entries, *[p for p in current if p not in entries]])
        elif kind == "append-non-duplicate":
            env[name] = os.pathsep.join([*current, *[e for e in entries if e not in current]])
        elif kind == "set":
            env[name] = entries[0] if values else ""
        elif kind == "set-if-unset":
            env.setdefault(name, entries[0] if values else "")


def _stable_name(name: str) -> str:
    """Hide the Python version in paths (python3.11 -> python3.X, py3.11 -> py3.X) for stable outputs."""
    return re.sub(r"(python|py)3\.\d+", r"\g<1>3.X", name)


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
            lines.append(f"{indent}{branch}{_stable_name(entry.name)}/")
            lines += _tree_lines(entry, indent + ("    " if last else "│   "), depth - 1)
        else:
            lines.append(f"{indent}{branch}{_stable_name(entry.name)}")
    return lines
