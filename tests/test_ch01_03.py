"""Chapters 01-03: architecture helpers, timing measurements and sensor nodes (checkers: test_ch03_checkers).

Real nodes over real Fast DDS. Timing bounds are loose: the machine has 2 shared cores.
"""

from __future__ import annotations

import math
import threading
import time

import pytest
import rclpy
from rclpy.node import Node
from std_msgs.msg import Float64

from course_helpers import CourseError
from course_helpers.chapters.ch01_architecture import (
    ChatterCounter,
    NamedTalker,
    classify_port,
    count_during,
    layer_stack,
    loaded_libraries,
    transports_in_use,
)
from course_helpers.chapters.ch02_executors import measure_blocking, measure_timer_jitter, spin_for
from course_helpers.chapters.ch03_topics import (
    ArrayListener,
    ImuPublisher,
    TemperatureSensor,
    imu_message,
    make_sensor_array,
    measure_bandwidth,
    message_size,
    quaternion_from_rpy,
    sensor_topics,
    sent_rate,
)
from course_helpers.chapters.ch04_services import IsolatedExecutor
from course_helpers.solutions import ch03_topics as solution
from tests.timing import assert_timing

# measures time (rates, latencies, DDS events): make test's timing stage, few workers beside it
pytestmark = pytest.mark.timing


# ---------------------------------------------------------------------- chapter 01
def test_layer_stack_finds_fastrtps_rmw_and_fast_dds(rt):
    layers = {layer.name: layer for layer in layer_stack()}
    assert rclpy.get_rmw_implementation_identifier() == "rmw_fastrtps_cpp"
    assert "librmw_fastrtps_cpp.so" in layers["rmw_fastrtps_cpp"].libraries
    assert any(lib.startswith("libfastrtps.so") for lib in layers["Fast DDS"].libraries)
    assert all(layer.loaded for layer in layers.values()), layers
    assert layers["Fast DDS"].version.startswith("2.")
    assert "librcl.so" in loaded_libraries(r"^librcl\.so")


def test_transports_show_shared_memory_and_unicast_ports(rt):
    with IsolatedExecutor(namespace="/ports"):  # a sandbox's kept participant, whatever ran here before
        pass
    transports = transports_in_use(rt.domain.domain_id)
    assert transports.uses_shm and any(f.startswith("fastrtps_") for f in transports.shm_files)
    meanings = [meaning for _port, meaning in transports.udp_ports]
    assert any(m.startswith("discovery, unicast") for m in meanings), meanings
    assert any(m.startswith("user data, unicast") for m in meanings), meanings
    # every socket has a name: each participant's graph reader listens on a port of its own (7000-7399).
    # This process has the runtime's participant and at least the sandbox's kept one (core/kept_contexts.py).
    participants = sum(m.startswith("discovery, unicast") for m in meanings)
    assert participants >= 2, meanings
    assert meanings.count("graph updates (ros_discovery_info), a port of their own") == participants, meanings
    assert not [m for m in meanings if m.startswith("another")], meanings


def test_port_classification_follows_the_rtps_mapping():
    assert classify_port(7400, 0) == "discovery, multicast"
    assert classify_port(7410, 0) == "discovery, unicast (participant 0)"
    assert classify_port(7400 + 250 * 5 + 13, 5) == "user data, unicast (participant 1)"


def test_killing_one_node_process_leaves_the_others_talking(rt):
    a = rt.spawn("talker_a", NamedTalker, {"name": "talker_a", "rate_hz": 20}, wait_for="/talker_a")
    rt.spawn("talker_b", NamedTalker, {"name": "talker_b", "rate_hz": 20}, wait_for="/talker_b")
    counter = rt.add(ChatterCounter)
    rt.wait_until(lambda: counter.counts["talker_a"] and counter.counts["talker_b"], 60, "both talkers")
    assert_timing("both talkers are heard, more than 5 messages a second each",
                  lambda: count_during(counter, 1.0),
                  lambda heard: heard["talker_a"] > 5 and heard["talker_b"] > 5)
    a.kill()
    assert not a.alive and a.returncode == -9  # SIGKILL: nothing more can come from it
    assert_timing("the survivor keeps talking", lambda: count_during(counter, 1.0),
                  lambda heard: heard["talker_b"] > 5)


# ---------------------------------------------------------------------- chapter 02
def test_blocking_callback_stalls_a_single_threaded_executor(rt):
    single = measure_blocking("single", separate_groups=False, duration_s=1.5, block_s=0.3)
    assert single.max_gap_s > 0.3, single.max_gap_s  # the planner blocks the one thread for 0.3 s
    assert single.tick_count > 0


def test_one_default_group_stalls_even_with_many_threads(rt):
    multi = measure_blocking("multi", separate_groups=False, duration_s=1.5, block_s=0.3)
    assert multi.max_gap_s > 0.3, multi.max_gap_s


def test_separate_callback_groups_with_threads_keep_the_timer_regular(rt):
    block_s = 0.3
    # no gap as long as a planner call (the signature of waiting for one, as in the tests above), and
    # more ticks than a loop that waited for each of the 1.5 s / 0.3 s planner calls could make
    assert_timing("separate groups on several threads: the timer never waits for the planner",
                  lambda: measure_blocking("multi", separate_groups=True, duration_s=1.5, block_s=block_s),
                  lambda fixed: fixed.max_gap_s < block_s and fixed.tick_count > 2 * 1.5 / block_s)


def test_a_busy_callback_delays_a_timer_of_its_thread_only(rt):
    idle = measure_timer_jitter(period_s=0.01, duration_s=1.5)
    loaded = measure_timer_jitter(period_s=0.01, duration_s=1.5, heavy_ms=20)
    assert not idle.due_while_busy() and not idle.busy
    # one thread: every call that fell due during the 20 ms callback waited for its end (on any machine)
    blocked = loaded.due_while_busy()
    assert len(blocked) >= 5 and all(call.waited_for_it for call in blocked), loaded.busy_summary()
    # idle, a call starts about when it falls due: in the median, sooner than the calls above, which
    # waited for the rest of a busy callback
    assert_timing("an idle timer starts its calls sooner than one behind a busy callback",
                  lambda: measure_timer_jitter(period_s=0.01, duration_s=1.5),
                  lambda quiet: quiet.percentile_ms(50) < statistics_median([c.wait_ms for c in blocked]))
    # another thread and group: some such calls started while the busy callback still ran
    assert_timing("with another thread and group, some calls start while the busy callback runs",
                  lambda: measure_timer_jitter(period_s=0.01, duration_s=1.5, heavy_ms=20, executor="multi",
                                               separate_groups=True),
                  lambda run: any(not call.waited_for_it for call in run.due_while_busy()))


def test_due_while_busy_sorts_calls_by_the_busy_runs():
    from course_helpers.chapters.ch02_executors import JitterResult

    ms = 1_000_000
    result = JitterResult("made up", 0.01, calls=[(0, 1 * ms), (10 * ms, 18 * ms), (20 * ms, 23 * ms)],
                          busy=[(8 * ms, 16 * ms), (19 * ms, 25 * ms)])
    found = result.due_while_busy()
    assert [(c.wait_ms, c.left_ms, c.waited_for_it) for c in found] == [(8.0, 6.0, True), (3.0, 5.0, False)]


def statistics_median(values):
    ordered = sorted(values)
    return ordered[len(ordered) // 2]


def test_spin_for_rejects_bad_arguments(rt):
    with pytest.raises(CourseError):
        spin_for(TemperatureSensor, 1.0, executor="threads")
    with pytest.raises(CourseError):
        measure_timer_jitter(heavy_ms=50, heavy_period_s=0.03)


class FailingTimer(Node):
    def __init__(self):
        super().__init__("failing_timer")
        self.timer = self.create_timer(0.01, self.tick)

    def tick(self):
        raise ZeroDivisionError("the callback failed")


@pytest.mark.parametrize("executor", ["single", "multi"])
def test_spin_for_raises_a_callback_error_after_cleaning_up(rt, executor):
    with pytest.raises(ZeroDivisionError, match="the callback failed"):
        spin_for(FailingTimer, 0.3, executor)
    assert not [t.name for t in threading.enumerate() if t.name.startswith("spin_for")]
    assert "/failing_timer" not in rt.nodes()


# ---------------------------------------------------------------------- chapter 03 nodes
def test_quaternion_and_imu_message_describe_the_tilt():
    x, y, z, w = quaternion_from_rpy(0, 0, 90)
    assert math.isclose(z, math.sin(math.pi / 4)) and math.isclose(w, math.cos(math.pi / 4))
    msg = imu_message(roll_deg=30)
    assert math.isclose(solution.tilt_deg(msg.orientation), 30.0, abs_tol=1e-9)
    assert math.isclose(msg.linear_acceleration.z, 9.80665 * math.cos(math.radians(30)))
    assert message_size(imu_message(frame_id="imu_0")) == 324


def test_imu_publisher_tilt_can_be_changed_live(rt):
    imu = rt.add(ImuPublisher, rate_hz=50)
    imu.set_tilt(roll_deg=20)
    rt.wait_until(lambda: imu.sent > 3, 5, "IMU messages")
    msg = rt.wait_for_messages("/imu", "sensor_msgs/msg/Imu", count=1)[0]
    assert math.isclose(solution.tilt_deg(msg.orientation), 20.0, abs_tol=1e-6)


def test_temperature_sensor_publishes_a_sine_between_20_and_30_celsius(rt):
    rt.add(TemperatureSensor, rate_hz=50)
    msgs = rt.wait_for_messages("/sensor/temperature", Float64, count=5)
    assert all(20.0 <= m.data <= 30.0 for m in msgs)


def test_temperature_sensor_runs_in_a_child_process(rt):
    rt.spawn("thermo_hot", TemperatureSensor, {"name": "thermo_hot", "mean_c": 30.0, "amplitude_c": 1.0},
             wait_for="/thermo_hot")
    msgs = rt.wait_for_messages("/sensor/temperature", Float64, count=3)
    assert all(29.0 <= m.data <= 31.0 for m in msgs)


def test_array_listener_counts_every_topic_of_a_sensor_array(rt):
    rt.spawn("sensor_array", make_sensor_array, {"count": 3, "rate_hz": 20}, wait_for="/sensor_array")
    meter = rt.add(ArrayListener, sensor_topics(3))
    rt.wait_until(lambda: meter.messages >= 30, 10, "messages from the three sensors")
    assert meter.bytes == meter.messages * message_size(imu_message(frame_id="imu_0"))


def test_sensor_array_reports_what_it_sent_over_the_channel(rt):
    array = rt.spawn("sensor_array", make_sensor_array, {"count": 2, "rate_hz": 50}, wait_for="/sensor_array")

    def rate_over_a_second() -> float:
        start = time.monotonic()
        time.sleep(1.0)  # the measurement window
        return sent_rate(array, start, time.monotonic())

    assert_timing("two sensors at 50 Hz report about 100 messages a second (more than half of it)",
                  rate_over_a_second, lambda rate: 50 < rate <= 2 * 50 * 1.1)
    counts = [report["count"] for report in array.reports("sent")]
    assert counts == sorted(counts) and counts[-1] > 0, counts


def test_bandwidth_grows_with_message_size(rt):
    small, large = assert_timing(
        "the meter keeps up, and the bigger messages carry more than 100 x the bytes",
        lambda: measure_bandwidth(rt, sizes=(100, 50_000), rate_hz=50, duration_s=0.8),
        lambda samples: all(s.sent_hz > 10 and s.received_hz > 0.8 * s.sent_hz for s in samples)
        and samples[1].bytes_per_s > 100 * samples[0].bytes_per_s)
    assert math.isclose(large.bytes_per_s / large.received_hz, large.wire_bytes, rel_tol=0.01)
    # the same messages on both sides: what arrived of those sent in the window, never more
    rates = [(s.sent_hz, s.received_hz) for s in (small, large)]
    assert all(received <= sent for sent, received in rates), rates
