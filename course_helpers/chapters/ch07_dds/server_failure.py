"""Chapter 01's failure experiment again, with a discovery server where ROS 1 had its master.

A discovery server brings back a centre for discovery, so :func:`server_failure_experiment` asks
chapter 01's questions of it: two clients (a talker and a listener) talk; the server is killed;

1. does the running pair keep talking? (data never went through the server: yes)
2. does a new client find the talker? (it can only ask the server: no)
3. after the server restarts on the same address, does the newcomer find the talker, and when?
   Clients keep announcing themselves to their server, so a restarted server learns of them again
   (a restarted ROS 1 master never does): measured here, usually within a few seconds.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from course_helpers.chapters.ch07_dds.listener import ReportingListener
from course_helpers.chapters.ch07_dds.server import free_udp_port, start_discovery_server
from course_helpers.core.dds_config import LEASE_S
from course_helpers.core.waiting import poll_until
from course_helpers.nodes.chatter import make_talker

RATE_HZ = 10.0
KEEP_TALKING_MESSAGES = 5
START_TIMEOUT_S = 20.0
MIN_WINDOW_S = 2.0  # a newcomer gets at least this long (and twice what the first listener needed)
LABELS = ("server_talker", "server_listener", "server_newcomer")


@dataclass
class ServerFailureResult:
    """What the experiment measured (times in seconds)."""

    first_message_s: float  # the first listener, from its start to its first message
    kept_talking: bool  # KEEP_TALKING_MESSAGES more messages after the server was killed
    kept_talking_s: float | None
    newcomer_heard_without_server: bool
    window_s: float  # how long the newcomer was given while the server was down
    newcomer_after_restart_s: float | None  # from the restart to the newcomer's first message
    restart_wait_s: float  # how long that was awaited (None above: nothing within this long)


def _heard(child) -> int:
    return len(child.reports("heard"))


def server_failure_experiment(rt, topic: str = "server_chatter",
                              restart_wait_s: float = LEASE_S + 10.0) -> ServerFailureResult:
    """Run the experiment with child processes of ``rt``; stops the clients and the server at the end.

    ``restart_wait_s``: how long to wait, after the restart, for the newcomer to hear the talker
    (at most the lease, ``LEASE_S``, and some: by then every client has called the server again).
    """
    port = free_udp_port()
    server = start_discovery_server(port)
    env = server.client_env()
    try:
        rt.spawn(LABELS[0], make_talker, params={"name": LABELS[0], "topic": topic, "rate_hz": RATE_HZ},
                 env=env)
        started = time.monotonic()
        listener = rt.spawn(LABELS[1], ReportingListener, params={"name": LABELS[1], "topic": topic}, env=env)
        listener.wait_for_report("heard", START_TIMEOUT_S, "the first client to hear the talker")
        first = time.monotonic() - started
        server.child.kill()  # SIGKILL: a crash
        server.stop()
        before, killed_at = _heard(listener), time.monotonic()
        kept = poll_until(lambda: _heard(listener) >= before + KEEP_TALKING_MESSAGES, 5.0)
        kept_s = time.monotonic() - killed_at if kept else None
        window = max(MIN_WINDOW_S, 2 * first)
        newcomer = rt.spawn(LABELS[2], ReportingListener, params={"name": LABELS[2], "topic": topic}, env=env)
        poll_until(lambda: _heard(newcomer) > 0 or not newcomer.alive, window)
        heard_alone = _heard(newcomer) > 0
        restarted_at = time.monotonic()
        server = start_discovery_server(port)  # the same address the clients were given
        poll_until(lambda: _heard(newcomer) > 0 or not newcomer.alive, restart_wait_s, period=0.05)
        after = time.monotonic() - restarted_at if _heard(newcomer) else None
        return ServerFailureResult(first, kept, kept_s, heard_alone, window, after, restart_wait_s)
    finally:
        rt.stop_children(list(LABELS))
        server.stop()
