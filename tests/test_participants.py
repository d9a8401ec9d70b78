"""DDS participants, as chapters 01 and 02 show them: one per rclpy context, created with its first node.

Real rclpy nodes over real Fast DDS, in this process, in a course child process and in a plain Python
process that imports nothing of the course's runtime. What is asserted is what the mechanism
guarantees: which sockets a process holds after each step (a participant binds and closes them while it
is created and deleted), which GUID prefix the graph gives each node, and that a chain of round trips
completes. The round-trip times themselves are only measured.
"""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import textwrap

import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Int64

from course_helpers import CourseError
from course_helpers.chapters.ch01_architecture import Echo, Pinger, bounce
from course_helpers.chapters.ch02_executors import ParticipantWatch
from course_helpers.core.participants import (
    Participant,
    participant_of,
    participant_of_gid,
    participant_of_node,
    participants_in_graph,
)
from course_helpers.core.udp_sockets import is_graph_port

from .conftest import REPO


# ---------------------------------------------------------------------- GUID prefixes
def test_a_prefix_names_its_process_and_its_id_there():
    gid = bytes([0x01, 0x0F, 0x78, 0xFD, 0xEC, 0x1F, 0xA7, 0x0A, 0x02, 0x00, 0x01, 0x00, 9, 9, 9, 9])
    participant = participant_of_gid(list(gid))  # rclpy gives a list of ints
    assert participant.prefix == gid[:12]
    assert participant.process == gid[:8]
    assert participant.number == 2  # the id; the next two bytes count its earlier use
    assert str(participant) == "01.0f.78.fd.ec.1f.a7.0a | 02.00.01.00"


def test_nodes_of_one_context_share_a_participant_and_a_child_has_its_own(rt):
    rt.add(Echo, "echo_one")
    rt.add(Echo, "echo_two")
    rt.spawn("echo_child", Echo, {"name": "echo_child"}, wait_for="/echo_child")
    one, two, child = (participant_of(rt, fqn) for fqn in ("/echo_one", "/echo_two", "/echo_child"))
    assert one == two
    assert child.process != one.process  # another process: Fast DDS's first 8 bytes differ
    assert {one, child} <= set(participants_in_graph(rt.graph))
    assert participant_of_node(rt.graph, "/no_such_node") is None
    # nodes whose every topic is shared (/rosout, /parameter_events), in two processes: each gets its own
    rt.node("plain_here")
    rt.spawn("plain_child", Node, {"node_name": "plain_child"}, wait_for="/plain_child")
    assert participant_of(rt, "/plain_here") == one
    assert participant_of(rt, "/plain_child").process != one.process
    checked = set()
    for info in rt.graph.get_publishers_info_by_topic("/rosout"):
        if info.node_name.startswith("_NODE_"):  # rmw knows no node for it: a process starting or leaving
            continue
        fqn = info.node_namespace.rstrip("/") + "/" + info.node_name
        assert participant_of_node(rt.graph, fqn) == participant_of_gid(info.endpoint_gid), fqn
        checked.add(fqn)
    assert {"/plain_here", "/plain_child"} <= checked, checked


# ---------------------------------------------------------------------- chapter 02: when a participant exists
def _footprint_steps(rt, contexts: int):
    """The steps of notebook 02's cell, the second node in a context of its own if ``contexts`` is 2."""
    watch = ParticipantWatch(rt)
    first_context, second_context = Context(), Context()
    for context in (first_context, second_context)[:contexts]:
        rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    watch.step("init")
    first = Node("first", context=first_context)
    watch.step("first node", first)
    second = Node("second", context=second_context if contexts == 2 else first_context)
    watch.step("second node", second)
    first.destroy_node()
    watch.step("first destroyed")
    second.destroy_node()
    watch.step("second destroyed")
    for context in (first_context, second_context)[:contexts]:
        rclpy.shutdown(context=context)
    return watch


def _moved(watch, label: str) -> str:
    """What step ``label`` changed, for a failure's message."""
    return (f"{label}: opened {watch.opened(label)}, closed {watch.closed(label)}, new participants "
            f"{watch.new_participants(label)}, gone {watch.gone_participants(label)}")


def test_init_creates_no_participant_the_first_node_does_and_the_last_one_ends_it(rt):
    watch = _footprint_steps(rt, contexts=1)
    assert watch.unchanged("init") and not watch.own_ports_mapped("init"), \
        f"{_moved(watch, 'init')}, mapped {watch.mapped('init')}"
    opened = watch.opened("first node")
    assert sum(is_graph_port(port) for _address, port in opened) == 1, opened
    base = 7400 + 250 * rt.domain.domain_id
    unicast = [port for _address, port in opened if 0 <= port - base - 10 < 240]
    assert len(unicast) == 2 and unicast[1] == unicast[0] + 1, opened  # discovery, user data
    assert f"fastrtps_port{unicast[1]}" in watch.own_ports_mapped("first node")  # the check sees its own
    [created] = watch.new_participants("first node")
    assert watch.created("first node") == watch.participant("/first") == created
    assert watch.created("init") is None and watch.deleted("first destroyed") is None
    assert created.process == watch.process and created != participant_of(rt, "/_course_runtime")
    assert watch.unchanged("second node"), _moved(watch, "second node")
    assert watch["second node"].nodes["/second"] == created
    assert watch.unchanged("first destroyed"), _moved(watch, "first destroyed")
    assert watch.closed("second destroyed") == opened
    assert watch.gone_participants("second destroyed") == [created] == [watch.deleted("second destroyed")]
    assert watch["second destroyed"].participants == watch["before"].participants


def test_a_dropped_node_that_the_collector_destroys_later_is_not_a_steps_doing(rt):
    """An earlier cell's node, dropped inside a reference cycle, is the last of its context: Python's cyclic
    collector destroys it at a moment nobody chose, closing its participant's sockets. (CI run X: 'second
    node' changed something.) The watch collects before it records, so the collection below is no step's."""
    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    cycle = {"node": Node("dropped", context=context)}
    cycle["self"] = cycle
    del cycle
    try:
        watch = ParticipantWatch(rt)
        gc.collect()  # the collector runs between two steps, as it may during any allocation
        watch.step("nothing")
        assert watch.unchanged("nothing"), _moved(watch, "nothing")
    finally:
        rclpy.shutdown(context=context)


def test_a_node_in_another_context_brings_a_participant_of_its_own(rt):
    watch = _footprint_steps(rt, contexts=2)
    assert watch.unchanged("init")  # two rclpy.init() calls: still nothing
    assert not watch.unchanged("second node")  # the check that passes above fails here
    assert sum(is_graph_port(port) for _address, port in watch.opened("second node")) == 1
    assert watch["second node"].nodes["/second"] != watch["first node"].nodes["/first"]
    assert len(watch["second node"].participants) == len(watch["before"].participants) + 2
    assert not watch.unchanged("first destroyed")  # each node was the last of its context
    assert watch.created("second node") == watch.participant("/second") != watch.created("first node")
    assert watch.deleted("first destroyed") == watch.participant("/first")


def test_a_step_needs_a_label_of_its_own(rt):
    watch = ParticipantWatch(rt)
    with pytest.raises(CourseError, match="label of its own"):
        watch.step("before")
    with pytest.raises(CourseError, match="no step 'later'"):
        watch.opened("later")
    with pytest.raises(CourseError, match="first record"):
        watch.opened("before")
    with pytest.raises(CourseError, match="no step recorded node '/first'"):
        watch.participant("/first")


PLAIN_PROCESS = """
    import json
    import rclpy
    from rclpy.node import Node
    from course_helpers.core.mapped_files import shm_files
    from course_helpers.core.udp_sockets import udp_sockets

    def footprint():
        return {"udp": [port for _address, port in udp_sockets()], "shm": shm_files()}

    steps = {"start": footprint()}
    rclpy.init()
    steps["init"] = footprint()
    first = Node("first")
    steps["first node"] = footprint()
    second = Node("second")
    steps["second node"] = footprint()
    first.destroy_node()
    second.destroy_node()
    steps["both destroyed"] = footprint()
    rclpy.shutdown()
    print(json.dumps(steps))
"""


def test_a_plain_rclpy_process_opens_its_ports_with_its_first_node(rt):
    """No course runtime and no course profile: rclpy, rmw_fastrtps and Fast DDS as a ROS program has them."""
    env = {k: v for k, v in os.environ.items() if k != "FASTRTPS_DEFAULT_PROFILES_FILE"}
    env.update(ROS_DOMAIN_ID=str(rt.domain.domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PYTHONPATH=REPO)
    result = subprocess.run([sys.executable, "-c", textwrap.dedent(PLAIN_PROCESS)], capture_output=True,
                            text=True, timeout=60, env=env, cwd=REPO)
    assert result.returncode == 0, result.stderr
    steps = json.loads(result.stdout.strip().splitlines()[-1])
    assert steps["start"] == steps["init"] == {"udp": [], "shm": []}, steps
    first = steps["first node"]
    assert sum(is_graph_port(port) for port in first["udp"]) == 1, first
    base = 7400 + 250 * rt.domain.domain_id
    user_data = [port for port in first["udp"] if 0 <= port - base - 10 < 240 and (port - base) % 2]
    assert len(user_data) == 1, first
    user_data = user_data[0]
    queue = f"fastrtps_port{user_data}"  # its user-data port's shared-memory queue: the same number
    assert queue in first["shm"], first
    assert steps["second node"]["udp"] == first["udp"]
    # deleted with the last node: its sockets and its port's queue are gone (Fast DDS may keep a segment
    # of a peer it read from mapped in the process: a cache, not a participant)
    gone = steps["both destroyed"]
    assert gone["udp"] == [] and queue not in gone["shm"], steps


# ---------------------------------------------------------------------- chapter 01: nodes in one process
@pytest.mark.timing
def test_round_trips_to_an_echo_here_and_in_a_child_all_come_back(rt):
    here = rt.add(Echo, "echo_here")
    rt.spawn("echo_far", Echo, {"name": "echo_far"}, wait_for="/echo_far")
    pinger = rt.add(Pinger, ["echo_here", "echo_far"])
    trips = bounce(rt, pinger, 30)
    assert {echo: len(times) for echo, times in trips.seconds.items()} == {"echo_here": 30, "echo_far": 30}
    assert all(0 < s < 60 for seconds in trips.seconds.values() for s in seconds)
    assert 0 < trips.fastest_us("echo_far") <= trips.one_way_us("echo_far")
    # in one process the echo got a copy: rclpy has no intra-process hand-over of the object
    assert here.last == pinger.sent["echo_here"] and here.last is not pinger.sent["echo_here"]
    again = bounce(rt, pinger, 5)  # a second run ignores nothing of its own and counts afresh
    assert [len(s) for s in again.seconds.values()] == [5, 5]


def test_a_pinger_ignores_an_answer_it_is_not_waiting_for(rt):
    rt.add(Echo, "echo_here")
    pinger = rt.add(Pinger, ["echo_here"])
    rt.wait_until(pinger.matched, 10, "the pinger to match its echo")

    def stray_answer_during_a_run():
        pinger.start(1)  # the ping is in flight: its answer comes in a later callback
        pinger.on_pong("echo_here", Int64(data=pinger.sent["echo_here"].data - 1))  # an older number
        return list(pinger.round_trips["echo_here"])

    assert rt.call_in_executor(stray_answer_during_a_run) == []


def test_bad_echoes_and_rounds_are_named(rt):
    with pytest.raises(CourseError, match="list of echo node names"):
        rt.add(Pinger, "echo_here")
    with pytest.raises(CourseError, match="invalid node name"):
        rt.add(Pinger, ["echo/here"])
    pinger = rt.add(Pinger, ["echo_here"])
    with pytest.raises(CourseError, match="rounds must be a whole number"):
        bounce(rt, pinger, 0)
    assert isinstance(participant_of(rt, "/pinger"), Participant)
