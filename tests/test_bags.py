"""The bag engine (core/bags) against real nodes: record, read, play, and rosbag2's own files.

* a bag the course records from a node in another process is read back, message for message, by an
  independent reader (the ``mcap`` and ``mcap-ros2-support`` libraries, which decode with the
  definitions stored in the file, not with the venv's types);
* the course reads a bag that rosbag2 itself wrote (``tests/data/rosbag2_cdr_test``), and both
  readers agree on it;
* ``metadata.yaml`` is what Jazzy's rosbag2 writes (version 9, offered QoS as a list of profiles with
  the policies by name, the type hash the graph reports);
* a transient-local topic is played back as transient-local, and a subscriber that joins after its
  message was played still gets it;
* a bag replayed under a SimClock gives the same output on every run.
"""

from __future__ import annotations

import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from course_helpers.core import bags
from course_helpers.core.bags import types
from course_helpers.core.sim_clock import SimClock
from course_helpers.nodes import Talker

from .conftest import REPO

ROSBAG2_BAG = f"{REPO}/tests/data/rosbag2_cdr_test"
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


def _mcap_file(path) -> str:
    return str(next(path.glob("*.mcap")))


def read_ros2_messages(path: str, topics=None):
    """(topic, log time ns, decoded message) for each message, decoded by mcap-ros2-support from the
    definitions stored in the file (the venv's message classes are not used)."""
    with open(path, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        return [(channel.topic, message.log_time, decoded)
                for _schema, channel, message, decoded in reader.iter_decoded_messages(topics=topics)]


def test_a_recorded_bag_is_read_back_message_for_message_by_mcap_ros2(rt, tmp_path):
    rt.spawn("bag_talker", Talker, {"name": "bag_talker", "topic": "bag_chatter", "rate_hz": 50.0},
             wait_for="/bag_talker")
    recording = bags.record(rt, tmp_path / "talk", ["/bag_chatter"])
    rt.wait_until(lambda: "/bag_chatter" in recording.topics, 5, "the recorder to subscribe")
    rt.wait_until(lambda: recording._writer.stats.received >= 20, 10, "20 recorded messages")
    stats = recording.stop()
    rt.stop_child("bag_talker")
    ours = [(stamp, msg.data) for stamp, msg in bags.read(tmp_path / "talk", "/bag_chatter")]
    theirs = [(stamp, msg.data) for _topic, stamp, msg in read_ros2_messages(_mcap_file(tmp_path / "talk"))]
    assert ours == theirs and len(ours) == stats.written >= 20
    numbers = [int(text.split()[1]) for _stamp, text in ours]
    assert numbers == sorted(numbers) and len(set(numbers)) == len(numbers)  # in order, none twice
    assert [stamp for stamp, _ in ours] == sorted(stamp for stamp, _ in ours)


def test_nested_and_course_types_decode_from_the_definitions_in_the_file(rt, tmp_path):
    from course_interfaces.msg import ExperimentSample

    source = rt.node("bag_source")
    odom = source.create_publisher(Odometry, "bag_odom", 10)
    sample = source.create_publisher(ExperimentSample, "bag_sample", 10)
    recording = bags.record(rt, tmp_path / "typed", ["/bag_odom", "/bag_sample"])
    rt.wait_until(lambda: len(recording.topics) == 2, 5, "the recorder to subscribe to both topics")
    rt.wait_until(lambda: odom.get_subscription_count() and sample.get_subscription_count(), 5, "matching")
    for n in range(3):
        message = Odometry()
        message.header.frame_id = "odom"
        message.pose.pose.position.x = 0.5 * n
        message.twist.covariance[35] = float(n)
        odom.publish(message)
        sample.publish(ExperimentSample(seq=n, stamp_ns=-n, payload=bytes([n]) * 4))
    rt.wait_until(lambda: recording._writer.stats.received == 6, 5, "six messages recorded")
    recording.stop()
    decoded = {}
    for topic, _stamp, msg in read_ros2_messages(_mcap_file(tmp_path / "typed")):
        decoded.setdefault(topic, []).append(msg)
    odoms = decoded["/bag_odom"]
    assert [(o.header.frame_id, o.pose.pose.position.x, o.twist.covariance[35]) for o in odoms] \
        == [("odom", 0.5 * n, float(n)) for n in range(3)]
    assert [(s.seq, s.stamp_ns, bytes(s.payload)) for s in decoded["/bag_sample"]] \
        == [(n, -n, bytes([n]) * 4) for n in range(3)]


def test_metadata_is_what_jazzy_writes(rt, tmp_path):
    source = rt.node("bag_latcher")
    publisher = source.create_publisher(String, "bag_latched", LATCHED)
    recording = bags.record(rt, tmp_path / "meta", ["/bag_latched"], storage="sqlite3")
    rt.wait_until(lambda: recording.topics, 5, "the recorder to subscribe")
    rt.wait_until(lambda: publisher.get_subscription_count(), 5, "matching")
    publisher.publish(String(data="kept"))
    rt.wait_until(lambda: recording._writer.stats.received == 1, 5, "the message recorded")
    recording.stop()
    text = (tmp_path / "meta" / "metadata.yaml").read_text()
    info = yaml.safe_load(text)["rosbag2_bagfile_information"]
    assert list(info) == ["version", "storage_identifier", "duration", "starting_time", "message_count",
                          "topics_with_message_count", "compression_format", "compression_mode",
                          "relative_file_paths", "files", "custom_data", "ros_distro"]
    assert (info["version"], info["storage_identifier"], info["ros_distro"]) == (9, "sqlite3", "jazzy")
    topic = info["topics_with_message_count"][0]["topic_metadata"]
    offer = topic["offered_qos_profiles"][0]  # a list of profiles (version 9), not a string (version 8)
    assert list(offer) == ["history", "depth", "reliability", "durability", "deadline", "lifespan",
                           "liveliness", "liveliness_lease_duration", "avoid_ros_namespace_conventions"]
    assert (offer["reliability"], offer["durability"], offer["history"]) == ("reliable", "transient_local",
                                                                               "unknown")
    announced = rt.graph.get_publishers_info_by_topic("/bag_latched")[0].topic_type_hash
    assert topic["type_description_hash"] == f"RIHS01_{bytes(announced.value).hex()}" \
        == types.definition("std_msgs/msg/String")[1]  # the graph's hash, and the one the .msg files give


def test_the_course_reads_a_bag_rosbag2_wrote_and_both_readers_agree():
    info = bags.bag_info(ROSBAG2_BAG)
    assert (info.storage, info.version, info.message_count) == ("mcap", 7, 7)
    assert {(t.name, t.type, t.count) for t in info.topics} == {
        ("/array_topic", "test_msgs/msg/Arrays", 4), ("/test_topic", "test_msgs/msg/BasicTypes", 3)}
    assert all(q.durability.name == "TRANSIENT_LOCAL" for t in info.topics for q in t.offered)
    basic = bags.read(ROSBAG2_BAG, "/test_topic")
    assert [m.int32_value for _stamp, m in basic] == [123, 123, 123]
    arrays = bags.read(ROSBAG2_BAG, "/array_topic")
    assert list(arrays[0][1].string_values) == ["Complex Hello1", "Complex Hello2", "Complex Hello3"]
    theirs = [(stamp, list(msg.string_values))
              for _t, stamp, msg in read_ros2_messages(f"{ROSBAG2_BAG}/cdr_test_0.mcap", ["/array_topic"])]
    assert theirs == [(stamp, list(m.string_values)) for stamp, m in arrays]
    text = bags.format_info(info)
    assert "Messages:          7" in text
    assert "Topic: /test_topic | Type: test_msgs/msg/BasicTypes | Count: 3" in text


def test_a_transient_local_topic_replays_as_transient_local_and_a_late_subscriber_gets_it(rt, tmp_path):
    source = rt.node("bag_map_server")
    latched = source.create_publisher(String, "bag_map", LATCHED)
    stream = source.create_publisher(String, "bag_ticks", 10)
    latched.publish(String(data="the map"))  # before the recorder exists: it still gets it (transient local)
    recording = bags.record(rt, tmp_path / "latched", ["/bag_map", "/bag_ticks"])
    rt.wait_until(lambda: recording._writer.stats.received >= 1, 5, "the latched map recorded")
    rt.wait_until(lambda: stream.get_subscription_count(), 5, "matching")
    for n in range(15):  # the bag goes on for 1.5 s after the map
        stream.publish(String(data=f"tick {n}"))
        rt.poll_until(lambda: False, 0.1)
    recording.stop()
    rt.remove(source)
    playback = bags.play(rt, tmp_path / "latched")
    rt.wait_until(lambda: playback.published["/bag_map"] == 1, 5, "the map played")
    offers = [info.qos_profile for info in rt.graph.get_publishers_info_by_topic("/bag_map")]
    assert [p.durability for p in offers] == [DurabilityPolicy.TRANSIENT_LOCAL]
    late = rt.node("bag_late_joiner")
    heard: list[str] = []
    late.create_subscription(String, "bag_map", lambda msg: heard.append(msg.data), LATCHED)
    assert playback.running  # the player still plays the ticks
    rt.wait_until(lambda: heard == ["the map"], 5, "the late subscriber to get the map")
    assert playback.wait() == {"/bag_map": 1, "/bag_ticks": 15}


class Counter(Node):
    """Counts /bag_ticks messages and reports the count, with its ROS time, every 0.25 s of ROS time."""

    def __init__(self):
        super().__init__("bag_tick_counter")
        self.count = 0
        self.reports: list[tuple[float, int]] = []
        self.create_subscription(String, "bag_ticks", self.on_tick, 10)
        self.timer = self.create_timer(0.25, self.report)

    def on_tick(self, _msg) -> None:
        self.count += 1

    def report(self) -> None:
        self.reports.append((self.get_clock().now().nanoseconds / 1e9, self.count))


def test_a_bag_replayed_under_a_sim_clock_gives_the_same_output_every_run(rt, tmp_path):
    writer = bags.BagWriter(tmp_path / "ticks")
    writer.add_topic("/bag_ticks", "std_msgs/msg/String", [])
    from rclpy.serialization import serialize_message

    for n in range(20):  # uneven gaps: 0.03 s to 0.22 s
        writer.write("/bag_ticks", 5_000_000_000 + sum(30_000_000 + 10_000_000 * (k % 20) for k in range(n)),
                     serialize_message(String(data=str(n))))
    writer.close()
    runs = []
    for _ in range(2):
        clock = SimClock(rt, start_s=5.0)
        node = clock.drive(rt.build(Counter))
        replay = bags.SimReplay(rt, clock, tmp_path / "ticks")
        assert replay.run() == 20
        clock.advance(0.5)
        runs.append(node.reports)
        replay.close()
        clock.close()
        node.destroy_node()
    assert runs[0] == runs[1] and runs[0][-1][1] == 20
    assert [t for t, _ in runs[0]][:3] == [5.25, 5.5, 5.75]  # the timers ran on the bag's clock, exactly
