"""The failure experiment, on ROS 1 and on ROS 2: what still works when a process dies.

ROS 1 (:func:`ros1_failure_experiment`): a master, a rospy talker and listener. Kill the master, then

1. does the running pair keep talking? (their TCPROS link is peer to peer: yes)
2. does a new listener hear the talker? (it must ask the master where the talker is: no)
3. what does a restarted master know? (registrations lived only in the dead process: not the pair)

ROS 2 (:func:`ros2_failure_experiment`): a node (where the master would be), a talker and a
listener, each in its own process. Kill that first node, then ask the same three questions: the pair
goes on, a new listener finds the talker, and a restarted node sees every other one, because
discovery has no centre.

Each returns a :class:`FailureResult` with what was measured; :func:`side_by_side` puts two in a table.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from course_helpers.chapters.ch01_ros1.graph_watcher import GraphWatcher
from course_helpers.chapters.ch01_ros1.ros1 import start_master, start_rospy, stop_ros1
from course_helpers.core.errors import CourseError
from course_helpers.core.waiting import poll_until, wait_until
from course_helpers.nodes.chatter import Listener, make_talker

RATE_HZ = 10.0  # the talker's rate, both systems
KEEP_TALKING_MESSAGES = 5  # "the pair keeps talking" = this many more messages after the kill
KEEP_TALKING_TIMEOUT_S = 5.0
MIN_WINDOW_S = 2.0  # a newcomer gets at least this long (and twice what the first listener needed)
START_TIMEOUT_S = 20.0


@dataclass
class FailureResult:
    """What one failure experiment measured (times in seconds)."""

    system: str  # 'ROS 1' or 'ROS 2'
    killed: str  # what was killed
    first_message_s: float  # the first listener: from its start to its first message
    known_before: list[str]  # who the master (ROS 1) or the graph (ROS 2) knew before the kill
    kept_talking: bool  # the pair exchanged KEEP_TALKING_MESSAGES more messages after the kill
    kept_talking_s: float | None  # ... within this long
    newcomer_heard: bool  # a listener started after the kill heard the talker
    newcomer_s: float | None  # from its start to its first message (None: nothing heard)
    newcomer_window_s: float  # how long the newcomer was given
    restarted_knows: list[str]  # what the restarted master / node knows of the others
    restarted_s: float  # from the restart until that was known
    notes: list[str] = field(default_factory=list)


def _heard(child) -> int:
    return len(child.reports("heard"))


def _keeps_talking(listener) -> tuple[bool, float | None]:
    before, started = _heard(listener), time.monotonic()
    ok = poll_until(lambda: _heard(listener) >= before + KEEP_TALKING_MESSAGES, KEEP_TALKING_TIMEOUT_S)
    return ok, (time.monotonic() - started) if ok else None


def _first_message(child, window_s: float) -> float | None:
    started = time.monotonic()
    if poll_until(lambda: _heard(child) > 0 or not child.alive, window_s) and _heard(child):
        return time.monotonic() - started
    return None


def ros1_failure_experiment(topic: str = "/chatter") -> FailureResult:
    """Kill a live ROS 1 master under a talking pair (see the module docstring); stops everything after."""
    labels = ["talker", "listener", "newcomer"]
    master = start_master()
    try:
        start_rospy("talker", "talker", master, topic, RATE_HZ)
        listener = start_rospy("listener", "listener", master, topic)
        started = time.monotonic()
        listener.wait_for_report("heard", START_TIMEOUT_S, "the ROS 1 listener's first message")
        first = time.monotonic() - started
        known_before = master.nodes()
        master.kill()
        kept, kept_s = _keeps_talking(listener)
        window = max(MIN_WINDOW_S, 2 * first)
        newcomer = start_rospy("newcomer", "listener", master, topic)
        newcomer_s = _first_message(newcomer, window)
        restarted_at = time.monotonic()
        master = start_master(master.port)  # the same address: every node still knows it
        # the newcomer was still knocking (rospy retries every 0.2 s): give it time to get in
        poll_until(lambda: "/newcomer" in master.nodes(), 2.0, period=0.05)
        return FailureResult(
            system="ROS 1", killed="the master (rosmaster, SIGKILL)", first_message_s=first,
            known_before=known_before, kept_talking=kept, kept_talking_s=kept_s,
            newcomer_heard=newcomer_s is not None, newcomer_s=newcomer_s, newcomer_window_s=window,
            restarted_knows=master.nodes(), restarted_s=time.monotonic() - restarted_at,
            notes=["the newcomer's rospy.init_node waited for a master, and registered with the new one"])
    finally:
        stop_ros1(labels)
        master.stop()


def ros2_failure_experiment(rt, topic: str = "failure_chatter") -> FailureResult:
    """The same experiment on ROS 2, with child processes of ``rt``; stops them at the end.

    The node killed is the one started first, where ROS 1 had its master.
    """
    names = {"first": "first_node", "talker": "ros2_talker", "listener": "ros2_listener",
             "newcomer": "ros2_newcomer"}
    labels = [f"failure_{role}" for role in names]
    try:
        first_node = rt.spawn("failure_first", GraphWatcher, params={"name": names["first"]},
                              wait_for=f"/{names['first']}", timeout=START_TIMEOUT_S)
        rt.spawn("failure_talker", make_talker, params={"name": names["talker"], "topic": topic,
                                                        "rate_hz": RATE_HZ})
        started = time.monotonic()
        listener = rt.spawn("failure_listener", Listener, params={"name": names["listener"], "topic": topic,
                                                                  "report_heard": True})
        listener.wait_for_report("heard", START_TIMEOUT_S, "the ROS 2 listener's first message")
        first = time.monotonic() - started
        wanted = {f"/{names[role]}" for role in ("first", "talker", "listener")}
        poll_until(lambda: wanted <= set(rt.graph_nodes()), START_TIMEOUT_S)  # the graph fills in
        known_before = sorted(wanted & set(rt.graph_nodes()))
        first_node.kill()
        kept, kept_s = _keeps_talking(listener)
        window = max(MIN_WINDOW_S, 2 * first)
        newcomer = rt.spawn("failure_newcomer", Listener, params={"name": names["newcomer"], "topic": topic,
                                                                  "report_heard": True})
        newcomer_s = _first_message(newcomer, window)
        restarted_at = time.monotonic()
        restarted = rt.spawn("failure_first", GraphWatcher, params={"name": names["first"]})
        others = {f"/{names[role]}" for role in ("talker", "listener", "newcomer")}
        def sees_all() -> bool:
            return others <= set((restarted.last("graph") or {}).get("nodes", [])) or not restarted.alive

        wait_until(sees_all, START_TIMEOUT_S, "the restarted node to see the others")
        if not restarted.alive:
            raise restarted.failure("it saw the graph")
        knows = sorted(others & set(restarted.last("graph")["nodes"]))
        return FailureResult(
            system="ROS 2", killed=f"the first node (/{names['first']}, SIGKILL)", first_message_s=first,
            known_before=known_before, kept_talking=kept, kept_talking_s=kept_s,
            newcomer_heard=newcomer_s is not None, newcomer_s=newcomer_s, newcomer_window_s=window,
            restarted_knows=knows, restarted_s=time.monotonic() - restarted_at)
    finally:
        rt.stop_children(labels)


def side_by_side(*results: FailureResult) -> str:
    """A text table of failure experiments, one column per result, from what they measured."""
    if not results:
        raise CourseError("side_by_side() needs at least one FailureResult")

    def seconds(value):
        return "-" if value is None else f"{value:.2f} s"

    rows = [
        ("killed", [r.killed for r in results]),
        ("first message at start", [seconds(r.first_message_s) for r in results]),
        ("known before the kill", [", ".join(r.known_before) or "nobody" for r in results]),
        ("the pair kept talking", [f"yes, {KEEP_TALKING_MESSAGES} messages in {seconds(r.kept_talking_s)}"
                                   if r.kept_talking else "no" for r in results]),
        ("a new listener heard the talker", [f"yes, after {seconds(r.newcomer_s)}" if r.newcomer_heard
                                             else f"no, nothing in {seconds(r.newcomer_window_s)}"
                                             for r in results]),
        ("the restarted one knows", [", ".join(r.restarted_knows) or "nobody" for r in results]),
    ]
    width = max(len(label) for label, _ in rows) + 2
    columns = [max(len(r.system), *(len(values[i]) for _, values in rows)) + 2 for i, r in enumerate(results)]
    lines = [" " * width + "".join(r.system.ljust(columns[i]) for i, r in enumerate(results))]
    for label, values in rows:
        lines.append(label.ljust(width) + "".join(v.ljust(columns[i]) for i, v in enumerate(values)))
    return "\n".join(line.rstrip() for line in lines)
