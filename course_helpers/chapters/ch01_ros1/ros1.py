"""A live ROS 1 beside ROS 2: a real ``rosmaster`` and rospy nodes, started from the kernel.

ROS 1 (ros_comm 1.15) comes from the distribution's packages for its system Python, not from
PyPI, so the master and the rospy nodes run with that interpreter (``/usr/bin/python3``, or the
one named by ``COURSE_ROS1_PYTHON``). They are course children all the same: started through the
process layer, gone with the kernel. Everything stays on 127.0.0.1 (``ROS_IP``), and each kernel
runs its master on a free port of its own, so kernels never share a master.

* :func:`ros1_unavailable_reason`: None, or one line with the install command for this system;
* :func:`start_master` returns a :class:`Ros1Master`; its XML-RPC API (``getSystemState``,
  ``lookupNode``) shows what the master knows, through the standard library's ``xmlrpc.client``;
* :func:`start_rospy` runs ``rospy_talker.py`` or ``rospy_listener.py`` as a course child that
  reports over the process channel.
"""

from __future__ import annotations

import ast
import os
import socket
import threading
import xmlrpc.client
from dataclasses import dataclass

from course_helpers.core import processes
from course_helpers.core.errors import CourseError
from course_helpers.core.waiting import poll_until

PYTHON_ENV = "COURSE_ROS1_PYTHON"  # the interpreter ROS 1 is installed for
DEFAULT_PYTHON = "/usr/bin/python3"
PACKAGES = "python3-rospy python3-rosmaster python3-std-msgs python3-rosnode python3-rostopic"
GROUP = "ros1"
MASTER_LABEL = "ros1_master"
CALLER_ID = "/course_kernel"  # who the kernel says it is when it asks the master
XMLRPC_TIMEOUT_S = 2.0
MASTER_START_S = 15.0
HERE = os.path.dirname(os.path.abspath(__file__))
SCRIPTS = {role: os.path.join(HERE, f"rospy_{role}.py") for role in ("talker", "listener")}
# What each system carries (checked against the distributions' package indexes).
INSTALL = {
    "debian 12": f"sudo apt-get install {PACKAGES}",
    "ubuntu 22.04": f"sudo apt-get install {PACKAGES}  (from Ubuntu's universe component)",
    "ubuntu 24.04": "Ubuntu 24.04 has no ROS 1 packages: use a Debian 12 or Ubuntu 22.04 machine "
                    "or container",
}

MODULES = ("rospy", "rosmaster", "std_msgs.msg")  # what the master and the rospy nodes import
FIND_MODULES = f"""
import importlib.util
def found(name):
    try:
        return importlib.util.find_spec(name) is not None
    except ImportError:  # its package is missing
        return False
print([name for name in {MODULES!r} if not found(name)])
"""

_probe_lock = threading.Lock()
_probed: dict[str, str | None] = {}


def ros1_python() -> str:
    """The interpreter the ROS 1 packages belong to (``COURSE_ROS1_PYTHON``, else /usr/bin/python3)."""
    return os.environ.get(PYTHON_ENV) or DEFAULT_PYTHON


def install_hint(os_release: str = "/etc/os-release") -> str:
    """How to install ROS 1's Python packages here, in one line (Debian/Ubuntu; others: the package names)."""
    fields = {}
    try:
        with open(os_release, encoding="utf-8") as handle:
            for line in handle:
                key, _, value = line.strip().partition("=")
                fields[key] = value.strip('"')
    except OSError:
        pass
    system = f"{fields.get('ID', '')} {fields.get('VERSION_ID', '')}".strip()
    if system in INSTALL:
        return INSTALL[system]
    return (f"on Debian 12 or Ubuntu 22.04: sudo apt-get install {PACKAGES} "
            "(Ubuntu 24.04 has none)")


def ros1_unavailable_reason() -> str | None:
    """None if rospy and rosmaster import in :func:`ros1_python`; else one line with the install command."""
    python = ros1_python()
    with _probe_lock:
        if python not in _probed:
            _probed[python] = _probe(python)
        return _probed[python]


def _probe(python: str) -> str | None:
    if not os.path.exists(python):
        return f"ROS 1 is not installed ({python} does not exist): {install_hint()}"
    try:  # found, not imported: importing rospy takes half a second, and the master imports it anyway
        code, output = processes.run([python, "-c", FIND_MODULES], env=_plain_env(), timeout=60)
    except CourseError as error:
        return f"ROS 1 could not be checked with {python}: {error}"
    missing = output.strip().splitlines()[-1] if output.strip() else f"exit code {code}"
    if code != 0 or missing != "[]":
        return f"ROS 1 is not installed for {python} (missing: {missing}): {install_hint()}"
    return None


def _plain_env() -> dict:
    """The kernel's environment without what points Python at the course's venv."""
    return {"PYTHONPATH": None, "PYTHONHOME": None, "VIRTUAL_ENV": None}


def ros1_env(master_uri: str) -> dict:
    """Environment of a ROS 1 process: its master, loopback only, logs in the kernel's private folder."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(processes.__file__))))
    home = os.path.join(processes.log_dir(), "ros1_home")
    os.makedirs(home, exist_ok=True)
    return {**_plain_env(), "PYTHONPATH": root, "ROS_MASTER_URI": master_uri, "ROS_IP": "127.0.0.1",
            "ROS_HOSTNAME": None, "ROS_HOME": home, "ROS_LOG_DIR": os.path.join(home, "log")}


def free_tcp_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class _TimeoutTransport(xmlrpc.client.Transport):
    def make_connection(self, host):
        connection = super().make_connection(host)
        connection.timeout = XMLRPC_TIMEOUT_S
        return connection


@dataclass
class Ros1Master:
    """A ``rosmaster`` process on 127.0.0.1:``port``, and what it knows, asked over XML-RPC."""

    port: int
    child: processes.ChildProcess

    @property
    def uri(self) -> str:
        """``http://127.0.0.1:PORT/``: what ROS_MASTER_URI says to every ROS 1 process."""
        return f"http://127.0.0.1:{self.port}/"

    @property
    def alive(self) -> bool:
        return self.child.alive

    def api(self) -> xmlrpc.client.ServerProxy:
        """The master's XML-RPC API (``getSystemState``, ``lookupNode``, ``getPid`` ...)."""
        return xmlrpc.client.ServerProxy(self.uri, transport=_TimeoutTransport())

    def system_state(self) -> dict:
        """``getSystemState``: {'publishers': {topic: [nodes]}, 'subscribers': {...}, 'services': {...}}."""
        code, message, (pubs, subs, services) = self.api().getSystemState(CALLER_ID)
        if code != 1:
            raise CourseError(f"the ROS 1 master refused getSystemState: {message}")
        return {"publishers": {topic: sorted(nodes) for topic, nodes in pubs},
                "subscribers": {topic: sorted(nodes) for topic, nodes in subs},
                "services": {name: sorted(nodes) for name, nodes in services}}

    def nodes(self) -> list[str]:
        """Every node the master knows of (it knows a node only through what the node registered)."""
        state = self.system_state()
        return sorted({node for table in state.values() for nodes in table.values() for node in nodes})

    def lookup_node(self, name: str) -> str | None:
        """``lookupNode``: the node's XML-RPC URI, or None if the master does not know it."""
        code, _message, uri = self.api().lookupNode(CALLER_ID, name)
        return uri if code == 1 else None

    def answers(self) -> bool:
        """True if the master answers an XML-RPC call now."""
        try:
            return self.api().getPid(CALLER_ID)[0] == 1
        except (OSError, xmlrpc.client.Error):
            return False

    def kill(self) -> None:
        """SIGKILL, as a crash or a pulled power cord would end it."""
        self.child.kill()
        self.child.stop()

    def stop(self) -> None:
        """Stop this master (not whichever master now has its label)."""
        self.child.stop()


def start_master(port: int | None = None, label: str = MASTER_LABEL) -> Ros1Master:
    """Start ``rosmaster --core -p PORT`` (a free port if None) and wait until it answers.

    Raises CourseError with the one-line reason where ROS 1 is missing, or with the master's
    output if it does not answer within MASTER_START_S.
    """
    reason = ros1_unavailable_reason()
    if reason is not None:
        raise CourseError(reason)
    port = free_tcp_port() if port is None else int(port)
    argv = processes.program_argv(ros1_python(), "-c", "import rosmaster; rosmaster.rosmaster_main()",
                                  "--core", "-p", str(port))
    master = Ros1Master(port, processes.start(label, argv, group=GROUP, channel=False,
                                              env=ros1_env(f"http://127.0.0.1:{port}/")))
    if not (poll_until(lambda: not master.alive or master.answers(), MASTER_START_S, period=0.05)
            and master.alive):
        output = master.child.output_tail(1500)
        master.stop()
        raise CourseError(f"rosmaster did not answer on port {port} within {MASTER_START_S:g} s:\n{output}")
    return master


def start_rospy(label: str, role: str, master: Ros1Master, *args: str) -> processes.ChildProcess:
    """Run ``rospy_<role>.py NAME ...`` (role 'talker' or 'listener') against ``master``, as a course child.

    Args:
        label: the process label and the node's name.
        role: 'talker' (args: topic, rate in Hz) or 'listener' (args: topic).
    """
    if role not in SCRIPTS:
        raise CourseError(f"role must be one of {sorted(SCRIPTS)}, got {role!r}")
    argv = [ros1_python(), SCRIPTS[role], label, *map(str, args)]
    return processes.start(label, argv, group=GROUP, env=ros1_env(master.uri))


def rospy_source(role: str, parts=("Talker", "Listener", "main")) -> str:
    """The source of ``parts`` (top-level classes and functions) of ``rospy_<role>.py``, read from the file.

    The kernel cannot import rospy (it belongs to the system Python), so the notebook prints the
    nodes from the very file the ROS 1 child runs.
    """
    if role not in SCRIPTS:
        raise CourseError(f"role must be one of {sorted(SCRIPTS)}, got {role!r}")
    with open(SCRIPTS[role], encoding="utf-8") as handle:
        text = handle.read()
    lines = text.splitlines()
    found = ["\n".join(lines[node.lineno - 1:node.end_lineno]) for node in ast.parse(text).body
             if isinstance(node, (ast.ClassDef, ast.FunctionDef)) and node.name in parts]
    return "\n\n\n".join(found)


def stop_ros1(labels) -> None:
    """Stop these ROS 1 processes (the master too, if its label is among them)."""
    processes.stop(list(labels), group=GROUP)
