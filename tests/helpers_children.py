"""Child-process targets the tests start (a child imports its target, so they live in a module)."""

from __future__ import annotations

import os
import time

from course_helpers.core.channel import report


def count_then_report(count: int = 3) -> None:
    """A procedure: report each step, then the total, and return (the process exits)."""
    for i in range(count):
        report("step", i=i)
    report("done", total=count)


def report_after(delay_s: float = 2.0) -> None:
    """A procedure that reports 'late' after ``delay_s`` seconds, then exits."""
    time.sleep(delay_s)
    report("late", after_s=delay_s)


def fail_after_report() -> None:
    """A procedure that fails: the child reports the error and exits 1."""
    raise RuntimeError("measured nothing")


def udp_addresses(pid: int) -> list[str]:
    """The addresses that process ``pid``'s IPv4 UDP sockets are bound to."""
    import psutil

    return [c.laddr.ip for c in psutil.Process(pid).net_connections(kind="udp4") if c.laddr]


def report_participant_setup(seconds: float = 60.0) -> None:
    """A procedure: create a node (so the participant exists), report how the participant was set
    up (range, profile file, UDP addresses), then stay discoverable for ``seconds``."""
    from rclpy.node import Node

    from course_helpers.core.dds_config import PROFILE_ENV, RANGE_ENV
    from course_helpers.core.runtime import get_runtime

    get_runtime().add(Node, "setup_reporter")
    profile = os.path.basename(os.environ.get(PROFILE_ENV, ""))
    report("setup", range=os.environ.get(RANGE_ENV), profile=profile, udp=udp_addresses(os.getpid()))
    time.sleep(seconds)


def start_program_tree() -> None:
    """A procedure that starts a program with two children through the process layer, then waits.

    It is stopped by a signal (SIGTERM from its kernel, or the kernel's death).
    """
    from course_helpers.core import processes

    processes.start("grandchild-program",
                    processes.program_argv("sh", "-c", "sleep 300 & sleep 300 & wait"),
                    group="test", channel=False)
    time.sleep(300)


def block_holding_the_gil_when_stopped() -> None:
    """A procedure whose clean-up blocks in C without releasing the GIL, as a hung library call can:
    once it is stopped, no Python thread of the process runs again (the parent watchdog included)."""
    import ctypes

    try:  # the report inside: a stop signal that comes while report() still returns hangs here too
        report("waiting")
        time.sleep(300)
    finally:
        ctypes.PyDLL(None).sleep(300)  # libc's sleep(3), called with the GIL held


def hold_a_named_node(name: str, participants: int = 1) -> None:
    """A procedure: ``participants`` participants in this process (a node ``<name>_<i>`` in each, on
    the domain of the course's environment), report 'ready' with this process's UDP ports, then wait
    to be stopped or killed."""
    from rclpy.context import Context
    from rclpy.node import Node

    from course_helpers.core.dds_config import init_context
    from course_helpers.core.udp_sockets import udp_sockets

    domain = int(os.environ["ROS_DOMAIN_ID"])
    nodes = []
    for i in range(participants):
        context = Context()
        init_context(context, domain)
        nodes.append(Node(f"{name}_{i}", context=context))
    report("ready", ports=sorted({port for _, port in udp_sockets()}),
           profile=os.path.basename(os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE", "")))
    time.sleep(300)


def report_when_it_sees(name: str) -> None:
    """A procedure: a node ``watcher``; reports 'seen' once this process's graph lists node ``name``."""
    from rclpy.node import Node

    from course_helpers.core.runtime import get_runtime

    node = get_runtime().add(Node, "watcher")
    get_runtime().wait_until(lambda: name in [n for n, _ in node.get_node_names_and_namespaces()], 30,
                             f"this child to see {name}")
    report("seen", name=name)
    time.sleep(300)


def hold_a_bare_node(name: str) -> None:
    """A procedure: a node ``name`` without a single endpoint in this process's runtime (what rmw lists
    for a ghost: a name and nothing live), report 'ready', then wait to be stopped."""
    from course_helpers.core.node_hook import bare_node
    from course_helpers.core.runtime import get_runtime

    node = bare_node(get_runtime().context, name)
    report("ready", name=name)
    time.sleep(300)  # stays until stopped: node is kept alive meanwhile
    node.destroy_when_not_in_use()
