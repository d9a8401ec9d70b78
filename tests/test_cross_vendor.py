"""Another vendor on the same graph (notebook 07b): Eclipse Cyclone DDS, with no ROS at all, in the
runtime's own domain beside real rclpy nodes over Fast DDS.

* messages go both ways on ``rt/chatter`` (the ROS topic /chatter as DDS names it);
* a reliable Cyclone reader never matches a best-effort rclpy writer: a best-effort Cyclone reader in
  the same participant, discovered at the same time, receives that writer's samples (the sentinel),
  while the reliable one has no match and nothing, and the rclpy publisher's incompatible-QoS event
  callback names RELIABILITY;
* ``%ros2 topic info -v``'s source (the graph's endpoint info) and the graph snapshot show the Cyclone
  endpoints, and running cyclone_domain again leaves one participant, not two;
* a participant made before cyclone_domain gets a clear error instead of a second domain.

Skipped, with the install line, where the ``cyclonedds`` package is missing. (No ``from __future__
import annotations`` here: the binding reads the IDL struct's field types from its annotations.)
"""

import time
from dataclasses import dataclass

import pytest
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_policy_name_from_kind
from std_msgs.msg import String

from course_helpers import CourseError
from course_helpers.chapters.ch07_dds import cyclone
from course_helpers.core.udp_sockets import udp_sockets
from course_helpers.nodes.chatter import Listener, Talker
from course_helpers.viz.snapshot import BARE_DDS_NODE, graph_snapshot

REASON = cyclone.cyclone_unavailable_reason()
pytestmark = pytest.mark.skipif(REASON is not None, reason=str(REASON))
TIMEOUT_S = 15.0

if REASON is None:
    from cyclonedds.core import Policy, Qos
    from cyclonedds.domain import Domain, DomainParticipant
    from cyclonedds.idl import IdlStruct
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    @dataclass
    class String_(IdlStruct, typename="std_msgs::msg::dds_::String_"):  # noqa: N801 (the DDS name)
        data: str


class BestEffortTalker(Node):
    """A best-effort publisher whose incompatible-QoS event callback records the policy named."""

    def __init__(self, topic: str):
        super().__init__("best_effort_talker")
        self.incompatible = []  # the policies named, as they came
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        events = PublisherEventCallbacks(incompatible_qos=self.on_incompatible_qos)
        self.publisher = self.create_publisher(String, topic, qos, event_callbacks=events)
        self.timer = self.create_timer(0.05, self.tick)  # s

    def tick(self) -> None:
        self.publisher.publish(String(data="reading"))

    def on_incompatible_qos(self, event) -> None:
        self.incompatible.append(qos_policy_name_from_kind(event.last_policy_kind))


def take(reader, publisher, topic: str, rt, trace: str):
    """One sample from a Cyclone reader, waiting at most TIMEOUT_S (a hang bound). If none came, the
    failure says which side had matched which (Cyclone's reader, the rclpy publisher, the kernel's
    graph), how long it waited, the process's UDP ports and what Cyclone's trace says of participant
    discovery (seen twice in the logic stage: nothing matched on either side within 15 s)."""
    start = time.monotonic()
    try:
        return reader.take_one(timeout=duration(seconds=TIMEOUT_S))
    except StopIteration:
        waited = time.monotonic() - start
        matched = reader.get_subscription_matched_status()
        listed = [i.node_name for i in rt.graph.get_subscriptions_info_by_topic(topic)]
        raise AssertionError(
            f"no sample on {topic} after {waited:.1f} s: Cyclone's reader matched "
            f"{matched.current_count} writer(s) ({matched.total_count} ever); the rclpy publisher matched "
            f"{publisher.get_subscription_count()} reader(s); the kernel's graph lists readers of {listed}; "
            f"this process's UDP ports {sorted({port for _, port in udp_sockets()})}\n"
            f"{spdp_summary(trace)}"
        ) from None


def spdp_summary(trace: str, last: int = 12) -> str:
    """What Cyclone's trace says of participant discovery: its ports, how many participant
    announcements (SPDP) it received and sent, and the last few of them."""
    try:
        with open(trace, encoding="utf-8", errors="replace") as text:
            lines = text.read().splitlines()
    except OSError as exc:
        return f"no Cyclone DDS trace ({exc})"
    ports = [line.split(": ", 1)[-1] for line in lines if "Unicast Ports:" in line]
    received = [line for line in lines if " SPDP ST" in line]
    sent = [line for line in lines if "xmit spdp" in line or "ddsi_spdp_write" in line]
    recent = sorted(received + sent)[-last:]  # each line starts with its time
    return (f"Cyclone DDS trace {trace}: {'; '.join(ports) or 'no ports'}; {len(received)} SPDP received "
            f"({sum(' NEW ' in line for line in received)} new participants), {len(sent)} sent; the last:\n"
            + "\n".join(line[:200] for line in recent))


@pytest.fixture
def trace(tmp_path) -> str:
    return str(tmp_path / "cyclone_trace.log")


@pytest.fixture
def participant(rt, trace):
    cyclone.cyclone_domain(rt, trace_file=trace)
    yield DomainParticipant(rt.domain.domain_id)
    cyclone.close_cyclone()


def test_cyclone_and_rclpy_exchange_messages_both_ways(rt, participant, trace):
    topic = Topic(participant, "rt/chatter", String_)  # ROS's /chatter, as the DDS names it
    reader = DataReader(participant, topic, qos=Qos(Policy.History.KeepLast(10)))
    talker = rt.add(Talker, rate_hz=20.0, console=False)
    heard = [take(reader, talker.publisher, "/chatter", rt, trace).data for _ in range(3)]
    assert all(text.startswith("hello ") for text in heard), heard

    listener = rt.add(Listener, name="listener", console=False)
    writer = DataWriter(participant, topic, qos=Qos(Policy.History.KeepLast(10)))
    rt.wait_until(lambda: writer.get_publication_matched_status().current_count == 2  # its reader, ROS's
                  and listener.subscription.get_publisher_count() == 2, TIMEOUT_S, "both sides matched")
    for i in range(3):
        writer.write(String_(data=f"hello from Cyclone DDS {i}"))
    rt.wait_until(lambda: sum("Cyclone" in h for h in listener.heard) == 3, TIMEOUT_S, "the ROS listener")
    assert [h for h in listener.heard if "Cyclone" in h] == [f"hello from Cyclone DDS {i}" for i in range(3)]


def test_a_reliable_cyclone_reader_never_matches_a_best_effort_rclpy_writer(rt, participant, trace):
    topic = Topic(participant, "rt/sensor", String_)
    reliable = DataReader(participant, topic, qos=Qos(Policy.Reliability.Reliable(duration(seconds=1))))
    best_effort = DataReader(participant, topic, qos=Qos(Policy.Reliability.BestEffort))
    talker = rt.add(BestEffortTalker, "sensor", console=False)
    got = [take(best_effort, talker.publisher, "/sensor", rt, trace) for _ in range(3)]  # the sentinel
    rt.wait_until(lambda: talker.incompatible, TIMEOUT_S, "the incompatible-QoS event on the ROS side")
    assert len(got) == 3
    assert reliable.get_subscription_matched_status().current_count == 0
    assert reliable.take(100) == []
    assert reliable.get_requested_incompatible_qos_status().total_count >= 1
    assert talker.incompatible[0] == "RELIABILITY", talker.incompatible
    assert talker.publisher.get_subscription_count() == 1  # the best-effort reader only


def test_the_graph_shows_the_foreign_endpoints_and_a_rerun_leaves_one_participant(rt, participant):
    # A topic of its own: Fast DDS 2.14 keeps a departed Cyclone endpoint for Cyclone's lease (10 s)
    topic = Topic(participant, "rt/graph_chatter", String_)
    _writer, _reader = DataWriter(participant, topic), DataReader(participant, topic)

    def foreign() -> list:
        return [i for i in (*rt.graph.get_publishers_info_by_topic("/graph_chatter"),
                            *rt.graph.get_subscriptions_info_by_topic("/graph_chatter"))
                if i.node_name == BARE_DDS_NODE]

    rt.wait_until(lambda: len(foreign()) == 2, TIMEOUT_S, "Cyclone's writer and reader in the ROS graph")
    assert {bytes(i.endpoint_gid)[:2] for i in foreign()} == {b"\x01\x10"}  # vendor 01.10: Cyclone DDS
    assert {i.topic_type for i in foreign()} == {"std_msgs/msg/String"}
    snap = graph_snapshot(rt)
    # one box holds both endpoints: this participant's (earlier tests' Cyclone participants may still be
    # drawn, departed but within their lease, since Fast DDS 2.14 ignores Cyclone's goodbyes)
    (box,) = snap.publishers("/graph_chatter")
    assert box.startswith("[Eclipse Cyclone DDS ") and snap.subscribers("/graph_chatter") == [box], snap.nodes

    assert cyclone.cyclone_participants() == 1
    cyclone.cyclone_domain(rt)  # what running the cell again does: the old participant goes
    assert cyclone.cyclone_participants() == 0
    again = DomainParticipant(rt.domain.domain_id)
    assert cyclone.cyclone_participants() == 1 and again.get_children() == []


def test_a_participant_made_before_cyclone_domain_gets_a_clear_error(rt):
    cyclone.close_cyclone()
    made_by_hand = Domain(rt.domain.domain_id, cyclone.cyclone_config())  # not made by cyclone_domain
    try:
        with pytest.raises(CourseError, match="before cyclone_domain"):
            cyclone.cyclone_domain(rt)
    finally:
        made_by_hand.__del__()
    assert cyclone.cyclone_participants() == 0
