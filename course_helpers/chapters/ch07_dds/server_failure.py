"""Chapter 01's failure experiment again, with a discovery server where ROS 1 had its master.

A discovery server brings back a centre for discovery, so :func:`server_failure_experiment` asks
chapter 01's questions of it. Two clients (a talker and a listener) talk through a running server;
the server is killed;

1. does the running pair keep talking? (data never went through the server: yes)
2. does a new client find the talker? (it can only ask the server: no)
3. after the server restarts on the same address, does the newcomer find the talker? Yes, once every
   client has dropped the dead server. The restarted server has the same GUID prefix (it comes from the
   server ID). A client that still holds the dead one when it comes back takes it for the same
   participant: it never sends its endpoints again, and the new server never learns about the talker
   (eProsima/Fast-DDS#2534). A client drops a crashed server one lease after the server's last
   announcement; only then does it call the server again as a new one and tell it everything. So the
   experiment restarts the server after its lease has run out, and needs a server with a short lease
   (``start_discovery_server(lease_s=1.0)``).

It returns a :class:`~course_helpers.viz.failure_table.FailureResult`, the record chapter 01 fills
in for ROS 1 and ROS 2, so that the notebook can print them side by side.
"""

from __future__ import annotations

import time

from course_helpers.chapters.ch07_dds.listener import ReportingListener
from course_helpers.chapters.ch07_dds.server import DiscoveryServer, start_discovery_server
from course_helpers.core.errors import CourseError
from course_helpers.core.waiting import poll_until
from course_helpers.viz.failure_table import KEEP_TALKING_MESSAGES, FailureResult, seconds

KEEP_TALKING_TIMEOUT_S = 5.0
MAX_LEASE_S = 5.0  # the restart waits two of the server's leases: a longer lease is refused
WINDOW_FACTOR = 2  # the newcomer, once its node exists, gets this many times what the first pair needed
MIN_WINDOW_S = 1.0  # ... and at least this long
START_TIMEOUT_S = 20.0
NEWCOMER = "server_newcomer"


def _heard(child) -> int:
    return len(child.reports("heard"))


def _first_heard(child) -> float | None:
    stamps = child.channel.stamped("heard")
    return stamps[0][0] if stamps else None


def server_failure_experiment(rt, server: DiscoveryServer, talker, listener,
                              topic: str = "chatter") -> FailureResult:
    """Kill ``server`` under a talking pair of its clients and ask the three questions (module docstring).

    Args:
        server: the running discovery server.
        talker, listener: its clients, child processes of ``rt``; the listener reports ``heard``
            (:class:`ReportingListener`) and has heard the talker on ``topic``.

    The first pair needed ``first`` seconds to talk, from the moment both the server and the
    listener ran. A newcomer started while the server is down is watched for ``WINDOW_FACTOR x
    first`` (at least ``MIN_WINDOW_S``) from the moment its node exists. The server restarts once
    that window has passed and two of its leases have passed since the kill (one for the clients to
    drop it, one to spare); the newcomer then has ``START_TIMEOUT_S`` to hear the talker, as a new
    client has. The three clients and the server are stopped at the end.
    """
    if not server.alive or listener.last("heard") is None:
        raise CourseError("server_failure_experiment needs a running discovery server and a listener "
                          "that has heard the talker through it")
    if server.lease_s > MAX_LEASE_S:
        raise CourseError(f"server_failure_experiment restarts the server once its clients have dropped it, "
                          f"two leases after the kill: start it with a lease of at most {MAX_LEASE_S:g} s, "
                          f"e.g. start_discovery_server(port, lease_s=1.0) "
                          f"(this one has {server.lease_s:g} s)")
    first = _first_heard(listener) - max(server.child.started, listener.started)
    window = max(MIN_WINDOW_S, WINDOW_FACTOR * first)
    env, port, lease_s = server.client_env(), server.port, server.lease_s
    try:
        server.child.kill()  # SIGKILL: a crash
        server.stop()
        before, killed_at = _heard(listener), time.monotonic()
        kept = poll_until(lambda: _heard(listener) >= before + KEEP_TALKING_MESSAGES, KEEP_TALKING_TIMEOUT_S)
        kept_s = time.monotonic() - killed_at if kept else None
        newcomer = rt.spawn(NEWCOMER, ReportingListener, params={"name": NEWCOMER, "topic": topic}, env=env)
        newcomer.wait_for_report("ready", START_TIMEOUT_S, "the newcomer's node")
        ready = newcomer.channel.stamped("ready")[0][0]
        poll_until(lambda: _heard(newcomer) > 0 or not newcomer.alive, ready + window - time.monotonic())
        heard_alone = _first_heard(newcomer)
        time.sleep(max(0.0, killed_at + 2 * lease_s - time.monotonic()))  # every client has dropped it
        restarted_at = time.monotonic()
        server = start_discovery_server(port, lease_s=lease_s)  # the same address the clients were given
        poll_until(lambda: _heard(newcomer) > 0 or not newcomer.alive, START_TIMEOUT_S, period=0.02)
        heard_at = _first_heard(newcomer)
        after = None
        if heard_alone is not None:
            after_restart = "the newcomer had heard the talker before it"
        elif heard_at is not None:
            after = heard_at - restarted_at
            after_restart = f"the newcomer heard the talker {seconds(after)} after it"
        else:
            after_restart = f"the newcomer heard nothing in {seconds(START_TIMEOUT_S)}"
        return FailureResult(
            system="discovery server", killed="the server (SIGKILL)", first_message_s=first,
            kept_talking=kept, kept_talking_s=kept_s, newcomer_heard=heard_alone is not None,
            newcomer_s=None if heard_alone is None else heard_alone - newcomer.started,
            newcomer_window_s=ready + window - newcomer.started, after_restart=after_restart, restart_s=after)
    finally:
        rt.stop_children([talker.label, listener.label, NEWCOMER])
        server.stop()
