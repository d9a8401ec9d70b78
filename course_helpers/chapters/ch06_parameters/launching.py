"""A launch file's job without the launch package (which is not on PyPI): nodes started and stopped together.

:func:`launch` starts every :class:`NodeLaunch` in a child process of its own through the
runtime (``rt.spawn``), with its parameter file and values, as ``ros2 launch`` does;
:class:`LaunchGroup` stops the processes together, like Ctrl+C on ``ros2 launch``.
:func:`launch_file` writes the Python launch file that does the same in a ROS 2 installation.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

from course_helpers.chapters.ch06_parameters.files import params_file_arguments
from course_helpers.chapters.ch06_parameters.nodes import make_configured_node, node_class
from course_helpers.core.errors import CourseError
from course_helpers.core.names import full_name
from course_helpers.core.processes import ChildProcess
from course_helpers.core.runtime import get_runtime
from course_helpers.core.spawning import CHILD_HANG_S
from course_helpers.core.validation import check_namespace, check_node_name
from course_helpers.core.waiting import poll_until

OLD_NODES_GONE_S = 3.0  # how long a re-launch waits for the previous group's nodes to leave the graph


@dataclass
class NodeLaunch:
    """One node of a launch description: what :func:`launch` starts in a child process.

    ``kind`` is 'talker' or 'listener'; ``parameters`` (name -> value) override the values
    of ``params_file``.
    """

    kind: str
    name: str
    namespace: str = ""
    parameters: dict = field(default_factory=dict)
    params_file: str | None = None

    @property
    def fqn(self) -> str:
        """The node's full name: ``NodeLaunch('talker', 'talker', 'robot1').fqn == '/robot1/talker'``."""
        return full_name(check_namespace(self.namespace), self.name)

    def spawn_params(self) -> dict:
        """The keyword arguments of :func:`make_configured_node` for this node (JSON values).

        Raises :class:`CourseError` for an unknown kind, a bad name or a missing file.
        """
        node_class(self.kind)
        check_node_name(self.name)
        params_file = os.path.abspath(self.params_file) if self.params_file else None
        if params_file:
            params_file_arguments(params_file)  # checks that the file exists
        return {"kind": self.kind, "name": self.name, "namespace": check_namespace(self.namespace),
                "parameters": self.parameters, "params_file": params_file}


class LaunchGroup:
    """Nodes started together by :func:`launch`, each in its own child process."""

    def __init__(self, rt, label: str, members: list[tuple[ChildProcess, NodeLaunch]]):
        self.rt = rt
        self.label = label
        self.members = members

    @property
    def node_names(self) -> list[str]:
        """Full names of the group's nodes, sorted."""
        return sorted(entry.fqn for _, entry in self.members)

    @property
    def alive(self) -> bool:
        """True while every child process of the group runs."""
        return all(child.alive for child, _ in self.members)

    def stop(self) -> dict[str, int | None]:
        """Stop the group's processes together (SIGTERM to all, SIGKILL after a grace period).

        Returns the exit codes by node full name (0 for a clean stop).
        """
        running = self.rt.children()
        codes = self.rt.stop_children([child.label for child, _ in self.members
                                       if running.get(child.label) is child])
        return {entry.fqn: codes.get(child.label, child.returncode) for child, entry in self.members}

    def __repr__(self) -> str:
        state = "running" if self.alive else "stopped"
        return f"<LaunchGroup {self.label!r}: {', '.join(self.node_names)} ({state})>"


def launch(nodes: list[NodeLaunch], label: str = "launch", rt=None,
           timeout_s: float = CHILD_HANG_S) -> LaunchGroup:
    """Start every node of ``nodes`` in its own child process, then wait until all are in the graph.

    Args:
        nodes: the :class:`NodeLaunch` entries (distinct full names).
        label: names the group; re-running with the same label stops the previous group first.
        rt: the runtime (default: this kernel's).
        timeout_s: how long each node may take to appear [s]; it bounds a hang only (a node
            appears in a second or two, more on a busy machine).

    Returns the :class:`LaunchGroup`. If a process exits or a node does not appear in time,
    the group is stopped and the error (a CourseError or WaitTimeout with the process's
    output) is raised.
    """
    rt = rt or get_runtime()
    check_node_name(label)
    if not nodes or not all(isinstance(n, NodeLaunch) for n in nodes):
        raise CourseError("launch() takes a non-empty list of NodeLaunch(kind, name, namespace, parameters)")
    names = [n.fqn for n in nodes]
    if len(set(names)) != len(names):
        raise CourseError(f"two nodes would share a name: {sorted(names)}; give each a name or namespace")
    params = [entry.spawn_params() for entry in nodes]  # bad input fails before anything stops
    _stop_previous(rt, label)
    members = []
    try:
        for entry, kwargs in zip(nodes, params, strict=True):
            child_label = f"{label}__{entry.fqn.strip('/').replace('/', '_')}"
            members.append((rt.spawn(child_label, make_configured_node, params=kwargs), entry))
        for child, entry in members:  # the processes start in parallel; each is awaited in turn
            child.wait_for_report("ready", timeout_s, f"the start of node {entry.fqn}")
            rt.wait_for_child_node(child, entry.fqn, timeout_s)
    except BaseException:
        rt.stop_children([child.label for child, _ in members])
        raise
    return LaunchGroup(rt, label, members)


def _stop_previous(rt, label: str) -> None:
    """Stop the processes of an earlier group with ``label`` together; wait for their nodes to go."""
    previous = {name: child for name, child in rt.children().items() if name.startswith(label + "__")}
    old_nodes = {fqn for child in previous.values() for fqn in (child.last("ready") or {}).get("nodes", [])}
    rt.stop_children(list(previous))
    if old_nodes:
        poll_until(lambda: not old_nodes & set(rt.graph_nodes()), OLD_NODES_GONE_S)


def launch_file(nodes: list[NodeLaunch], package: str = "course_demo") -> str:
    """The Python launch file (``launch_ros.actions.Node`` entries) equivalent to ``nodes``.

    Args:
        nodes: the :class:`NodeLaunch` entries, as :func:`launch` takes them (may be empty).
        package: the ROS package that installs the ``talker`` and ``listener`` executables.

    Returns:
        The text of a file for ``ros2 launch <package> <file>.launch.py`` in a ROS 2 installation
        (it cannot run here: the ``launch`` packages are not on PyPI). Each entry's kind becomes
        the executable; its parameter file comes before its values, which override the file's.
    """
    if not isinstance(nodes, list) or not all(isinstance(n, NodeLaunch) for n in nodes):
        raise CourseError("launch_file() takes a list of NodeLaunch(kind, name, namespace, parameters)")
    lines = [
        "from launch import LaunchDescription",
        "from launch_ros.actions import Node",
        "",
        "",
        "def generate_launch_description():",
        "    return LaunchDescription([",
    ]
    for entry in nodes:
        node_class(entry.kind)
        parameters = ([entry.params_file] if entry.params_file else []) + (
            [dict(entry.parameters)] if entry.parameters else [])
        lines += ["        Node(",
                  f"            package={package!r},",
                  f"            executable={entry.kind!r},",
                  f"            name={entry.name!r},"]
        if entry.namespace:
            lines.append(f"            namespace={check_namespace(entry.namespace)!r},")
        if parameters:
            lines.append(f"            parameters={parameters!r},")
        lines.append("        ),")
    lines.append("    ])")
    return "\n".join(lines) + "\n"
