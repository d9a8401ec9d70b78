"""Checker of chapter 09 (packages): build the student's package with colcon and run its node.

:func:`check_package` takes the files of an ament_python package (relative path ->
text), writes them into a fresh colcon workspace in a temporary directory, runs
the real ``colcon build``, finds the console script the way ``ros2 run`` does,
starts it as its own process, and checks that its node joins the graph and
publishes. The workspace and the process are removed afterwards.

The node runs where only the ROS packages its package.xml declares (and theirs) are installed, as
on a robot set up with ``rosdep install`` (:mod:`course_helpers.chapters.ch09_packages.provisioned`):
a dependency the manifest forgot is not there, and the node cannot start. Only if it does not start
there does the checker run it again with every ROS package of this machine; if it starts then, the
manifest is what is missing (the two runs differ in nothing else).
"""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

from course_helpers.chapters.ch09_packages import (
    Workspace,
    read_manifest,
    stop_process,
    wait_for_process_node,
)
from course_helpers.checks import CheckReport
from course_helpers.core.dds_config import LEASE_S
from course_helpers.core.errors import CourseError, WaitTimeout

CTRL_C_EXIT_S = 5.0  # s a node may take to leave after Ctrl+C
# A process that ends without deleting its participant (killed, as this checker kills a node that
# ignores Ctrl+C) keeps its node in other processes' graphs until its lease ends: LEASE_S after the
# last announcement they heard. Fast DDS checks leases on its event thread, so allow half a lease more.
LEFTOVER_WAIT_S = 1.5 * LEASE_S

PACKAGE = "robot_heartbeat"
EXECUTABLE = "heartbeat"
NODE = "/heartbeat"
TOPIC = "/heartbeat"
MESSAGE_TYPE = "std_msgs/msg/String"
DEPENDS = "it runs where only the ROS packages its package.xml declares (and theirs) are installed"
LABEL = "checked_package"
CTRL_C_CRITERION = "Ctrl+C stops it cleanly"
# rclpy's SIGINT handler shuts the context down from another thread. If that happens between
# spin()'s check of the context and the wait set it then makes, rcl refuses the wait set and the
# process ends with this error however well main() catches KeyboardInterrupt (rclpy's executors.py;
# discussed in ros2/ros2cli#854 and ros2/rclpy#398). The checker forgives exactly this ending.
SHUTDOWN_RACE = ("RCLError: failed to initialize wait set: the given context is not valid, "
                 "either rcl_init() was not called or rcl_shutdown() was called.")
WAIT_SET_FRAME = re.compile(r'File ".*[/\\]rclpy[/\\]executors\.py", line \d+, in _wait_for_ready_callbacks$')


def check_package(files: dict, package: str = PACKAGE, executable: str = EXECUTABLE,
                  node: str = NODE, topic: str = TOPIC, msg_type: str = MESSAGE_TYPE, rt=None) -> CheckReport:
    """Build ``files`` as package ``package`` and run ``ros2 run package executable``.

    Args:
        files: the package's files, relative path -> text.
        package, executable, node, topic, msg_type: what the exercise asks for.
        rt: the runtime whose graph is watched (default: this kernel's).

    Returns:
        A :class:`CheckReport`. It passes when the package builds as an ament_python
        package, the executable is installed where ``ros2 run`` looks, its process shows node
        ``node`` in the graph where only the ROS packages its package.xml declares are
        installed, messages of ``msg_type`` arrive on ``topic``, and Ctrl+C stops it cleanly.
    """
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport(f"Package {package}: build it, run it, hear it")
    if not isinstance(files, dict):
        report.add("the package is a dict of files", False, f"got {type(files).__name__}",
                   "Write a dict: {'package.xml': '...', 'setup.py': '...', ...}.")
        return report
    if not _static_checks(report, files, package):
        return report

    with Workspace("checker_ws") as ws:
        try:
            ws.write_package(package, files)
        except CourseError as exc:
            report.add("the files can be written into src/", False, str(exc))
            return report
        build = ws.build(packages=None)
        if not report.add("colcon build succeeds", build.ok,
                          "" if build.ok else f"exit code {build.returncode}",
                          "Read the output below the report: a Python error in setup.py, or a "
                          "file setup.py lists that does not exist.\n" + build.log_tail(15)):
            return report
        kind = build.package_types.get(package, "not found")
        if not report.add("colcon identified an ament_python package", kind == "ros.ament_python",
                          f"type {kind}",
                          "colcon reads package.xml first; if it does not parse (a missing tag, an "
                          "invalid maintainer e-mail) it falls back to a plain Python package."):
            return report
        try:
            ws.find_executable(package, executable)
            found, detail = True, f"install/{package}/lib/{package}/{executable}"
        except CourseError as exc:
            found, detail = False, str(exc).split(". ")[0]
        declared = re.search(rf"{re.escape(executable)}\s*=\s*{re.escape(package)}\.\w+:\w+",
                             str(files["setup.py"]))
        if not report.add(f"`ros2 run {package} {executable}` finds the executable", found, detail,
                          ("setup.py has no console_scripts entry point for it: add "
                           f"entry_points={{'console_scripts': ['{executable} = {package}.MODULE:main']}}"
                           if declared is None else
                           f"setup.cfg must install scripts into $base/lib/{package} "
                           "([install] install_scripts=...), where `ros2 run` looks.")):
            return report
        _run_and_listen(report, rt, ws, package, executable, node, topic, msg_type)
    return report


def _static_checks(report: CheckReport, files: dict, package: str) -> bool:
    """Check the file list and package.xml before building; False stops the checker."""
    needed = ["package.xml", "setup.py", "setup.cfg", f"resource/{package}", f"{package}/__init__.py"]
    missing = [name for name in needed if name not in files]
    modules = [n for n in files if n.startswith(f"{package}/") and n.endswith(".py")
               and not n.endswith("__init__.py")]
    if not modules:
        missing.append(f"{package}/<node module>.py")
    ok = report.add("the files of an ament_python package are there", not missing,
                    f"missing: {', '.join(missing)}" if missing else f"{len(files)} files",
                    f"An ament_python package has package.xml, setup.py, setup.cfg, the marker "
                    f"resource/{package} (empty) and the Python package {package}/ with "
                    "__init__.py and the node's module.")
    if not ok:
        return False
    try:
        with tempfile.TemporaryDirectory() as tmp:
            manifest_path = Path(tmp) / "package.xml"
            manifest_path.write_text(str(files["package.xml"]))
            manifest = read_manifest(manifest_path)
    except CourseError as exc:
        report.add("package.xml is valid XML", False, str(exc),
                   "Compare with the package.xml of the demo above; every tag must be closed.")
        return False
    right = manifest["name"] == package and manifest["build_type"] == "ament_python"
    report.add(f"package.xml names {package} and declares the ament_python build type", right,
               f"name {manifest['name'] or '(none)'}, build type {manifest['build_type'] or '(none)'}",
               f"Use <name>{package}</name> and <export><build_type>ament_python</build_type></export>.")
    return True


def _run_and_listen(report: CheckReport, rt, ws: Workspace, package: str, executable: str,
                    node: str, topic: str, msg_type: str) -> None:
    alone = f"no other {node} runs before the package starts"  # the packaged process must show it
    if node in rt.nodes():
        report.add(alone, False, f"{node} is this notebook's own node, already in the graph",
                   f"Remove it first (rt.remove('{node}')), then check again.")
        return
    if node in rt.graph_nodes() and not _left_when_its_lease_ended(rt, node):
        report.add(alone, False, f"{node} is still in the graph after {LEFTOVER_WAIT_S:g} s: a running "
                   "process has it", "Stop the program that runs it (a terminal's `ros2 run`, another "
                   "notebook), then check again.")
        return
    try:
        provisioned = ws.provision(package)
    except CourseError as exc:
        report.add("the executable starts", False, str(exc).splitlines()[0])
        return
    try:
        child, appeared, detail = _start(report, ws, package, executable, node, provisioned)
        if child is None:
            return
        everything = None
        if not appeared and not child.alive:  # it ended (at an import?): again, with every ROS package
            child, everything, detail_everywhere = _start(report, ws, package, executable, node, None)
            if child is None:
                return
        if not report.add(f"its process shows node {node} in the graph", appeared or bool(everything),
                          detail if everything is None else detail_everywhere,
                          f"main() must call rclpy.init(), create the node (super().__init__("
                          f"'{node.strip('/')}')) and rclpy.spin() it."):
            return
        report.add(DEPENDS, appeared,
                   f"installed there: {provisioned.describe()}" if appeared else
                   f"where only {provisioned.describe()} are installed, it ended before its node appeared "
                   f"({detail.rsplit('; ', 1)[-1].strip()}); with every ROS package of this machine it runs",
                   "rosdep installs what package.xml names, and nothing else: declare every ROS package "
                   "your node imports (<depend> or <exec_depend>).")
        _listen_and_stop(report, rt, child, topic, msg_type)
    finally:
        stop_process(LABEL)


def _left_when_its_lease_ended(rt, node: str) -> bool:
    """Wait for ``node``, listed by another process, to leave the graph; False if it stays
    :data:`LEFTOVER_WAIT_S`. It leaves at its lease end if its process has ended without leaving."""
    print(f"{node} is in the graph, but not as this notebook's node. A program that was killed (as the "
          f"last check kills one that ignores Ctrl+C) stays listed until its lease ends ({LEASE_S:g} s): "
          f"waiting up to {LEFTOVER_WAIT_S:g} s for it to leave...", flush=True)
    try:
        rt.wait_until(lambda: node not in rt.graph_nodes(), LEFTOVER_WAIT_S, f"{node} to leave the graph")
    except WaitTimeout:
        return False
    print(f"{node} has left; checking the package.", flush=True)
    return True


def _start(report: CheckReport, ws: Workspace, package: str, executable: str, node: str, provisioned):
    """Run the executable (where ``provisioned`` says, or with everything when None): (child, whether
    ``node`` appeared, what its process said last if not), or (None, False, '') with the criterion
    "the executable starts" failed."""
    try:
        child = ws.run(package, executable, label=LABEL, provisioned=provisioned)
    except CourseError as exc:
        report.add("the executable starts", False, str(exc).splitlines()[0])
        return None, False, ""
    try:
        wait_for_process_node(child, node)
        return child, True, ""
    except (CourseError, WaitTimeout) as exc:  # it exited, or it runs without the node
        tail = [line for line in child.log().splitlines() if line.strip()][-3:]
        return child, False, "; ".join(tail) if tail else str(exc).splitlines()[0]


def rclpy_shutdown_race(lines: list[str]) -> bool:
    """Whether a process's output ends with rclpy's shutdown race: an RCLError refusing a context
    already shut down, raised where the executor makes its wait set (the traceback's last frame)."""
    frames = [line.strip() for line in lines if line.strip().startswith('File "')]
    if not frames or SHUTDOWN_RACE not in lines[-1]:  # frames: there are lines
        return False
    return WAIT_SET_FRAME.match(frames[-1]) is not None


def _listen_and_stop(report: CheckReport, rt, child, topic: str, msg_type: str) -> None:
    try:
        messages = rt.wait_for_messages(topic, msg_type, count=2, timeout=5.0)
        heard, detail = True, f"{len(messages)} messages of {type(messages[0]).__name__}"
    except Exception as exc:  # WaitTimeout or a wrong type name
        heard, detail = False, str(exc).splitlines()[0]
    report.add(f"messages arrive on {topic} from the packaged node", heard, detail,
               f"Publish {msg_type} on '{topic.strip('/')}' from a timer.")
    child.request_stop()  # SIGINT: what Ctrl+C in the terminal of `ros2 run` sends
    try:
        code = child.wait_for_exit(CTRL_C_EXIT_S, "it to leave after Ctrl+C")
    except WaitTimeout:
        code = None
    said = [line for line in child.log().splitlines() if line.strip()]
    race = code == 1 and rclpy_shutdown_race(said)
    last = f"; its last output: {' | '.join(said[-3:])}" if said else ""
    if code is None:
        detail = f"still running {CTRL_C_EXIT_S:g} s after Ctrl+C{last or '; it printed nothing'}"
    elif race:
        detail = ("exit code 1 from rclpy's own shutdown race, not from your code: its signal handler "
                  "ended the context while rclpy.spin() made its wait set (ros2/ros2cli#854)")
    else:
        detail = f"exit code {code}{last if code else ''}"
    report.add(CTRL_C_CRITERION, code == 0 or race, detail,
               "Catch KeyboardInterrupt (and rclpy.executors.ExternalShutdownException) around "
               "rclpy.spin(), then destroy the node and call rclpy.try_shutdown().")
