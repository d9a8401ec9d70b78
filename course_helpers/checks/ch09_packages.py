"""Checker of chapter 09 (packages): build the student's package with colcon and run its node.

:func:`check_package` takes the files of an ament_python package (relative path ->
text), writes them into a fresh colcon workspace in a temporary directory, runs
the real ``colcon build``, finds the console script the way ``ros2 run`` does,
starts it as its own process, and checks that its node joins the graph and
publishes. The workspace and the process are removed afterwards.
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
from course_helpers.core.errors import CourseError, WaitTimeout

CTRL_C_EXIT_S = 5.0  # s a node may take to leave after Ctrl+C

PACKAGE = "robot_heartbeat"
EXECUTABLE = "heartbeat"
NODE = "/heartbeat"
TOPIC = "/heartbeat"
MESSAGE_TYPE = "std_msgs/msg/String"
DEPENDENCIES = ("rclpy", "std_msgs")


def check_package(files: dict, package: str = PACKAGE, executable: str = EXECUTABLE,
                  node: str = NODE, topic: str = TOPIC, msg_type: str = MESSAGE_TYPE,
                  dependencies: tuple[str, ...] = DEPENDENCIES, rt=None) -> CheckReport:
    """Build ``files`` as package ``package`` and run ``ros2 run package executable``.

    Args:
        files: the package's files, relative path -> text.
        package, executable, node, topic, msg_type, dependencies: what the exercise asks for.
        rt: the runtime whose graph is watched (default: this kernel's).

    Returns:
        A :class:`CheckReport`. It passes when the package builds as an ament_python
        package, the executable is installed where ``ros2 run`` looks, its process shows node
        ``node`` in the graph, messages of ``msg_type`` arrive on ``topic``, and Ctrl+C
        stops it cleanly.
    """
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport(f"Package {package}: build it, run it, hear it")
    if not isinstance(files, dict):
        report.add("the package is a dict of files", False, f"got {type(files).__name__}",
                   "Write a dict: {'package.xml': '...', 'setup.py': '...', ...}.")
        return report
    if not _static_checks(report, files, package, executable, dependencies):
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


def _static_checks(report: CheckReport, files: dict, package: str, executable: str,
                   dependencies: tuple[str, ...]) -> bool:
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
    lacking = [d for d in dependencies if d not in manifest["depends"]]
    report.add(f"package.xml declares what the node imports ({', '.join(dependencies)})", not lacking,
               f"missing: {', '.join(lacking)}" if lacking else "",
               "Add <exec_depend>rclpy</exec_depend> and one for each message package you import.")
    return True


def _run_and_listen(report: CheckReport, rt, ws: Workspace, package: str, executable: str,
                    node: str, topic: str, msg_type: str) -> None:
    label = "checked_package"
    if node in rt.graph_nodes():  # it must be the packaged process that shows the node
        report.add(f"no other {node} runs before the package starts", False,
                   f"{node} is already in the graph",
                   f"Remove the notebook's own node first (rt.remove('{node}')), or stop the "
                   "process that runs it, then check again.")
        return
    try:
        child = ws.run(package, executable, label=label)
    except CourseError as exc:
        report.add("the executable starts", False, str(exc).splitlines()[0])
        return
    try:
        try:
            wait_for_process_node(child, node)
            appeared, detail = True, ""
        except (CourseError, WaitTimeout) as exc:  # it exited, or it runs without the node
            appeared = False
            tail = [line for line in child.log().splitlines() if line.strip()][-3:]
            detail = "; ".join(tail) if tail else str(exc).splitlines()[0]
        if not report.add(f"its process shows node {node} in the graph", appeared, detail,
                          f"main() must call rclpy.init(), create the node (super().__init__("
                          f"'{node.strip('/')}')) and rclpy.spin() it."):
            return
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
        report.add("Ctrl+C stops it cleanly (exit code 0)", code == 0,
                   f"still running after {CTRL_C_EXIT_S:g} s" if code is None else f"exit code {code}",
                   "Catch KeyboardInterrupt (and rclpy.executors.ExternalShutdownException) around "
                   "rclpy.spin(), then destroy the node and call rclpy.try_shutdown().")
    finally:
        stop_process(label)

