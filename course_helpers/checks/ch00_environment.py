"""The environment check of chapter 00: is everything the course needs installed and isolated?

:func:`observe_environment` looks at the live kernel (the runtime, what imports, the sockets the
DDS participant opened); :func:`environment_report` judges those facts, one criterion each; and
:func:`check_environment` does both. Tests feed the report facts with one thing wrong to see each
criterion fail, and run the whole check in fresh processes where the environment really is wrong.
"""

from __future__ import annotations

import importlib
import sys
from dataclasses import dataclass, field

from course_helpers.checks import CheckReport
from course_helpers.core.domains import held_here
from course_helpers.core.udp_sockets import reachable_from_network, udp_sockets

REQUIRED_MESSAGES = ["std_msgs.msg", "std_srvs.srv", "geometry_msgs.msg", "sensor_msgs.msg",
                     "test_msgs.action"]
SUPPORTED_PYTHONS = ((3, 10), (3, 13))  # oldest and newest supported (major, minor)
MIDDLEWARE = "rmw_fastrtps_cpp"
SHOWN_SOCKETS = 4  # a failing report names this many sockets that the network can reach


@dataclass
class EnvironmentFacts:
    """What :func:`observe_environment` found in this kernel."""

    python: tuple[int, int]  # (major, minor)
    rclpy: str  # rclpy's version
    context_running: bool  # the runtime's context and executor ran when the check began
    rmw: str  # the rmw implementation rclpy loaded
    missing_messages: list[str] = field(default_factory=list)  # of REQUIRED_MESSAGES
    interfaces_built: bool = False  # course_interfaces imports
    domain_id: int = 0
    domain_chosen_by: str = "automatic"  # 'automatic' (reserved) or 'user' (ROS_DOMAIN_ID)
    domain_held: bool = False  # this process holds the domain's reservation
    udp_sockets: list[tuple[str, int]] = field(default_factory=list)  # (address, port) bound here


def observe_environment(rt) -> EnvironmentFacts:
    """The facts :func:`environment_report` judges, read from ``rt`` and this process.

    Whether the context runs is read before anything else, because asking the runtime for its
    status restarts a context that was shut down from outside. The sockets are read once the
    runtime's DDS participant exists (its first node creates it).
    """
    running = rt.running
    status = rt.status()
    rt.graph_nodes()  # the participant exists from here on, with its sockets
    return EnvironmentFacts(
        python=(sys.version_info.major, sys.version_info.minor),
        rclpy=status["rclpy"],
        context_running=running,
        rmw=status["rmw"],
        missing_messages=[m for m in REQUIRED_MESSAGES if not _importable(m)],
        interfaces_built=_importable("course_interfaces.srv"),
        domain_id=status["domain_id"],
        domain_chosen_by=status["domain_chosen_by"],
        domain_held=held_here(status["domain_id"]),
        udp_sockets=udp_sockets(),
    )


def environment_report(facts: EnvironmentFacts) -> CheckReport:
    """One criterion per requirement, judged from ``facts``; returns the report."""
    report = CheckReport("Environment check")
    oldest, newest = SUPPORTED_PYTHONS
    supported = oldest <= facts.python <= newest
    report.add(f"Python is a supported version ({oldest[0]}.{oldest[1]}-{newest[0]}.{newest[1]})", supported,
               "" if supported else f"this is Python {facts.python[0]}.{facts.python[1]}",
               hint="Create the venv with a supported Python: make PYTHON=python3.12 lab")
    stopped = "it was not running when the check began; the runtime started it again"
    report.add(f"rclpy {facts.rclpy} imports and its context is running", facts.context_running,
               "" if facts.context_running else stopped,
               hint="Something shut ROS down (rclpy.shutdown(), or an interrupt while rclpy's own signal "
                    "handler was installed). Run the notebook's cells again from the top.")
    report.add(f"middleware is {MIDDLEWARE}", facts.rmw == MIDDLEWARE,
               "" if facts.rmw == MIDDLEWARE else f"this kernel runs {facts.rmw}",
               hint="Unset RMW_IMPLEMENTATION; the course uses Fast DDS (rmw_fastrtps_cpp).")
    missing = facts.missing_messages
    report.add("message packages std_msgs, std_srvs, geometry_msgs, sensor_msgs, test_msgs",
               not missing, ", ".join(missing) and f"missing: {', '.join(missing)}",
               hint="Run `make lab` again; it installs everything in environment.txt.")
    report.add("the course's own interfaces (course_interfaces) are built", facts.interfaces_built,
               hint="Run `make lab` again; it builds interfaces/course_interfaces.")
    reserved = facts.domain_chosen_by == "automatic" and facts.domain_held
    report.add("this kernel has its own ROS domain", reserved,
               "" if reserved else f"domain {facts.domain_id} was set with ROS_DOMAIN_ID, not reserved",
               hint="Unset ROS_DOMAIN_ID and restart the kernel: the course then reserves a domain "
                    "no other kernel on this machine uses.")
    open_to_network = reachable_from_network(facts.udp_sockets)
    local = bool(facts.udp_sockets) and not open_to_network
    if local:
        detail = ""
    elif not facts.udp_sockets:
        detail = "this kernel has no UDP socket: no DDS participant was found"
    else:
        shown = ", ".join(f"{address}:{port}" for address, port in open_to_network[:SHOWN_SOCKETS])
        more = len(open_to_network) - SHOWN_SOCKETS
        detail = f"open to the network: {shown}" + (f" and {more} more" if more > 0 else "")
    report.add("discovery stays on this machine (the kernel's UDP sockets are all bound to 127.0.0.1)",
               local, detail,
               hint="The kernel's DDS participant listens beyond this computer. Did you set "
                    "ROS_AUTOMATIC_DISCOVERY_RANGE or FASTRTPS_DEFAULT_PROFILES_FILE yourself? Unset "
                    "them and restart the kernel; chapter 07 explains the discovery ranges.")
    return report


def check_environment(rt=None) -> CheckReport:
    """Check Python, rclpy, the middleware, the message packages, the course interfaces and isolation.

    ``rt`` is the course runtime (this kernel's by default). Returns a :class:`CheckReport`.
    """
    from course_helpers.core.runtime import get_runtime

    return environment_report(observe_environment(rt or get_runtime()))


def _importable(module: str) -> bool:
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True
