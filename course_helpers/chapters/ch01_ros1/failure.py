"""The failure experiment, on ROS 1 and on ROS 2: what still works when a process dies.

ROS 1 (:func:`ros1_failure_experiment`): a master, a rospy talker and listener. Kill the master, then

1. does the running pair keep talking? (their TCPROS link is peer to peer: yes)
2. does a new listener hear the talker? (it must ask the master where the talker is: no)
3. what does a restarted master know? (registrations lived only in the dead process: not the pair)

ROS 2 (:func:`ros2_failure_experiment`): a node (where the master would be), a talker and a
listener, each in its own process. Kill that first node, then ask the same three questions: the pair
goes on, a new listener finds the talker, and the killed node, started again, sees every other one,
because discovery has no centre.

Each returns a :class:`~course_helpers.viz.failure_table.FailureResult` with what was measured.
:func:`start_failure_experiment` runs the ROS 1 one in a thread of its own, so that another
experiment can run meanwhile (chapter 01's ROS 2, chapter 07's discovery server).
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import Future

from course_helpers.chapters.ch01_ros1.graph_watcher import GraphWatcher
from course_helpers.chapters.ch01_ros1.ros1 import GROUP, Ros1Master, start_master, start_rospy
from course_helpers.core import processes
from course_helpers.core.domains import reserve_spare_domain
from course_helpers.core.waiting import poll_until
from course_helpers.nodes.chatter import Listener, make_talker
from course_helpers.viz.failure_table import KEEP_TALKING_MESSAGES, FailureResult, names, seconds

RATE_HZ = 20.0  # the talker's rate, both systems
KEEP_TALKING_TIMEOUT_S = 5.0
MIN_WINDOW_S = 1.0  # a newcomer gets twice what the first listener needed, and at least this long
REGISTER_WAIT_S = 5.0  # at most this long, a restarted master is watched for the newcomer to register
START_TIMEOUT_S = 20.0
RESTARTED_LABEL = "failure_restarted"  # the ROS 2 first node, started again

_background_lock = threading.Lock()
_background: list[threading.Thread] = []


def _heard(child) -> int:
    return len(child.reports("heard"))


def _keeps_talking(listener) -> tuple[bool, float | None]:
    before, started = _heard(listener), time.monotonic()
    ok = poll_until(lambda: _heard(listener) >= before + KEEP_TALKING_MESSAGES, KEEP_TALKING_TIMEOUT_S)
    return ok, (time.monotonic() - started) if ok else None


def _first_heard_s(child) -> float | None:
    """From the child's start to its first 'heard' report (its own clock: the machine's monotonic one)."""
    stamps = child.channel.stamped("heard") if child.channel is not None else []
    return stamps[0][0] - child.started if stamps else None


def _window(first_s: float) -> float:
    return max(MIN_WINDOW_S, 2 * first_s)


def _newcomer_hears(child, window_s: float) -> float | None:
    """Seconds from the child's start to its first message, if that came within ``window_s``; else None."""
    poll_until(lambda: _heard(child) > 0 or not child.alive, child.started + window_s - time.monotonic())
    heard = _first_heard_s(child)
    return heard if heard is not None and heard <= window_s else None


def start_talking_pair(master: Ros1Master, topic: str = "/chatter"):
    """A rospy talker (``RATE_HZ``) and listener on ``master``; returns the listener once it has heard."""
    start_rospy("talker", "talker", master, topic, RATE_HZ)
    listener = start_rospy("listener", "listener", master, topic)
    listener.wait_for_report("heard", START_TIMEOUT_S, "the rospy listener's first message")
    return listener


def ros1_failure_experiment(master: Ros1Master | None = None, listener=None,
                            topic: str = "/chatter") -> FailureResult:
    """Kill a live ROS 1 master under a talking pair (see the module docstring); stops everything after.

    Args:
        master, listener: a running master and the rospy listener (label 'listener') that has heard
            its talker (label 'talker'), as chapter 01's cells start them. None, or a master or
            listener that is no longer running (a re-run cell), starts both here.
    """
    used: list[processes.ChildProcess] = []
    try:
        return _measure_ros1(used, master, listener, topic)
    finally:
        processes.stop_together(used)


def _measure_ros1(used: list, master, listener, topic: str) -> FailureResult:
    """The experiment on a running pair (started here if there is none). Every process it uses goes into
    ``used``, to be stopped after: these very processes, never whichever process has their label by then
    (a re-run cell may have started new ones)."""
    if master is None or listener is None or not (master.alive and listener.alive):
        master = start_master()
        used.append(master.child)
        listener = start_talking_pair(master, topic)
    used += [master.child, listener, *filter(None, [processes.get("talker", GROUP)])]
    return kill_the_master(master, listener, topic, used)


def kill_the_master(master: Ros1Master, listener, topic: str, used: list) -> FailureResult:
    """ROS 1's steps: kill the master under a talking pair, start a new listener, restart the master.

    ``listener`` is the rospy listener that hears the talker; every process started here goes into
    ``used``, for the caller to stop.
    """
    listener.wait_for_report("heard", START_TIMEOUT_S, "the rospy listener's first message")
    first = _first_heard_s(listener)
    known_before = master.nodes()  # getSystemState, over XML-RPC
    master.kill()  # SIGKILL: the master ends without a word to anyone
    kept, kept_s = _keeps_talking(listener)  # 1. does the pair keep talking?
    window = _window(first)
    newcomer = start_rospy("newcomer", "listener", master, topic)  # 2. rospy asks the master for the talker
    used.append(newcomer)
    newcomer_s = _newcomer_hears(newcomer, window)
    restarted_at = time.monotonic()
    master = start_master(master.port)  # 3. a new master at the same address: every node still knows it
    used.append(master.child)
    # the newcomer was still knocking (rospy retries): its registration shows the new master works
    poll_until(lambda: "/newcomer" in master.nodes(), REGISTER_WAIT_S, period=0.05)
    knows, restart_s = master.nodes(), time.monotonic() - restarted_at
    return FailureResult(
        system="ROS 1", killed="the master (rosmaster, SIGKILL)", first_message_s=first,
        kept_talking=kept, kept_talking_s=kept_s, newcomer_heard=newcomer_s is not None,
        newcomer_s=newcomer_s, newcomer_window_s=window,
        after_restart=f"the new master knows {names(knows)}", known_before=known_before,
        restarted_knows=knows, restart_s=restart_s,
        notes=["the newcomer's rospy registered with the new master as soon as it answered"])


def start_failure_experiment(master: Ros1Master | None = None, listener=None,
                             topic: str = "/chatter") -> Future:
    """Start :func:`ros1_failure_experiment` in a thread of its own and return at once.

    ``.result()`` of the returned Future gives the :class:`FailureResult` (or raises what the
    experiment raised) as soon as it is measured; the thread then stops the ROS 1 processes (rospy
    takes about a second to exit). A run started earlier is finished first, stops included, so a
    re-run cell never has two.
    """
    future: Future = Future()

    def run() -> None:
        used: list[processes.ChildProcess] = []
        try:
            future.set_result(_measure_ros1(used, master, listener, topic))
        except BaseException as error:  # handed to whoever asks for the result
            future.set_exception(error)
        finally:
            processes.stop_together(used)

    with _background_lock:
        for earlier in _background:
            earlier.join()
        _background.clear()
        thread = threading.Thread(target=run, name="ros1-failure", daemon=True)
        _background.append(thread)
        thread.start()
    return future


class Ros2Side:
    """ROS 2's side before the kill: a first node (a graph watcher), a talker and a listener (children).

    They run in the kernel's spare domain: the killed node, which its peers list until its lease runs
    out, never shows in the kernel's graph.
    """

    LABELS = ("failure_first", "failure_talker", "failure_listener")
    FIRST, TALKER, LISTENER = "/first_node", "/ros2_talker", "/ros2_listener"

    def __init__(self, rt, topic: str = "failure_chatter"):
        self.rt, self.topic = rt, topic
        self.env = {"ROS_DOMAIN_ID": str(reserve_spare_domain())}
        self.first_node = rt.spawn(self.LABELS[0], GraphWatcher, params={"name": self.FIRST[1:]},
                                   env=self.env)
        rt.spawn(self.LABELS[1], make_talker, params={"name": self.TALKER[1:], "topic": topic,
                                                      "rate_hz": RATE_HZ}, env=self.env)
        self.listener = rt.spawn(self.LABELS[2], Listener, params={"name": self.LISTENER[1:], "topic": topic,
                                                                   "report_heard": True}, env=self.env)

    @property
    def alive(self) -> bool:
        return all(child.alive for child in (self.first_node, self.listener)) and all(
            label in self.rt.children() for label in self.LABELS)

    def known_before(self) -> list[str]:
        """Wait until the pair talks and the first node sees it; who the first node knows, itself too."""
        self.listener.wait_for_report("heard", START_TIMEOUT_S, "the ROS 2 listener's first message")
        if not poll_until(lambda: _sees(self.first_node, {self.TALKER, self.LISTENER}), START_TIMEOUT_S):
            raise self.first_node.failure("it saw the talker and the listener")
        return sorted({self.FIRST} | set(self.first_node.last("graph")["nodes"]))


def _sees(child, wanted: set[str]) -> bool:
    """True once a GraphWatcher child has reported every node of ``wanted`` (or has ended)."""
    return wanted <= set((child.last("graph") or {}).get("nodes", [])) or not child.alive


def start_ros2_side(rt, topic: str = "failure_chatter") -> Ros2Side:
    """Start ROS 2's first node, talker and listener (returns at once); see :class:`Ros2Side`."""
    return Ros2Side(rt, topic)


def ros2_failure_experiment(rt, side: Ros2Side | None = None) -> FailureResult:
    """The same experiment on ROS 2, with child processes of ``rt``; stops them at the end.

    ``side``: from :func:`start_ros2_side` (None, or one no longer running, starts one here). The node
    killed is its first node, where ROS 1 had its master. After the kill it is started again, as a
    new process under the same name that also listens to the talker: it is the newcomer, and it
    tells what a restarted node knows.
    """
    if side is None or not side.alive:
        side = start_ros2_side(rt)
    try:
        return kill_the_first_node(rt, side)
    finally:
        rt.stop_children([*side.LABELS, RESTARTED_LABEL])


def kill_the_first_node(rt, side: Ros2Side) -> FailureResult:
    """ROS 2's steps: kill the first node's process under a talking pair, then start it again.

    The restarted process is a :class:`GraphWatcher` that also listens to the talker: it is the
    newcomer, and it tells what a restarted node knows. The caller stops the processes.
    """
    known_before = side.known_before()
    first_s = _first_heard_s(side.listener)
    side.first_node.kill()  # SIGKILL: its process ends without saying goodbye
    kept, kept_s = _keeps_talking(side.listener)  # 1. does the pair keep talking?
    window = _window(first_s)
    restarted = rt.spawn(RESTARTED_LABEL, GraphWatcher,  # 2. and 3. the same node in a new process
                         params={"name": side.FIRST[1:], "topic": side.topic}, env=side.env)
    # discovery finds it whenever its process is up: on a busy machine that may take longer than
    # the window ROS 1's newcomer got, so this one may wait as long as any start (its time is printed)
    newcomer_s = _newcomer_hears(restarted, max(window, START_TIMEOUT_S))
    others = {side.TALKER, side.LISTENER}
    if not poll_until(lambda: _sees(restarted, others), START_TIMEOUT_S) or not restarted.alive:
        raise restarted.failure("it saw the other nodes")
    seen_at = next(t for t, data in restarted.channel.stamped("graph") if others <= set(data["nodes"]))
    knows, restart_s = sorted(others), seen_at - restarted.started
    return FailureResult(
        system="ROS 2", killed=f"the first node ({side.FIRST}, SIGKILL)", first_message_s=first_s,
        kept_talking=kept, kept_talking_s=kept_s, newcomer_heard=newcomer_s is not None,
        newcomer_s=newcomer_s, newcomer_window_s=window,
        after_restart=f"it saw {names(knows)} after {seconds(restart_s)}", known_before=known_before,
        restarted_knows=knows, restart_s=restart_s,
        notes=["the newcomer is the killed node started again: it listens to the talker too"])
