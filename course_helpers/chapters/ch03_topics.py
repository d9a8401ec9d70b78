"""Sensor and command nodes for chapter 03 (topics), in the kernel or in child processes.

* :class:`TemperatureSensor` - ``std_msgs/msg/Float64`` on ``sensor/temperature``, a sine wave in °C
  (:func:`make_temperature_sensor` starts one in a child process);
* :class:`CmdVelPublisher` - ``geometry_msgs/msg/Twist`` on ``cmd_vel`` (m/s, rad/s);
* :class:`ImuPublisher` - ``sensor_msgs/msg/Imu`` on ``imu`` with a tilt you can set;
* :func:`make_sensor_array` - N IMU nodes at R Hz (the throughput exercise), with a service that
  reports how many messages they really sent;
* :func:`measure_bandwidth` / :func:`plot_bandwidth` - the message-size-versus-rate demo.

Every node is written the way a student would write it: a Node subclass, a timer instead of a sleep
loop, units in comments. The ``make_*`` functions are child-process targets for ``rt.spawn``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from geometry_msgs.msg import Twist
from rclpy.node import Node
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Imu
from std_msgs.msg import Float64, UInt8MultiArray
from std_srvs.srv import Trigger

from course_helpers.core.errors import CourseError

GRAVITY = 9.80665  # m/s²


def quaternion_from_rpy(roll_deg: float, pitch_deg: float, yaw_deg: float = 0.0):
    """Return the unit quaternion (x, y, z, w) of a roll-pitch-yaw rotation given in degrees.

    The rotation is yaw about z, then pitch about y, then roll about x (the ROS convention).
    """
    r, p, y = (math.radians(a) / 2 for a in (roll_deg, pitch_deg, yaw_deg))
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return (sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


def imu_message(roll_deg: float = 0.0, pitch_deg: float = 0.0, yaw_deg: float = 0.0,
                frame_id: str = "imu_link") -> Imu:
    """An Imu message of a robot standing still with this attitude (orientation and gravity)."""
    msg = Imu()
    msg.header.frame_id = frame_id
    x, y, z, w = quaternion_from_rpy(roll_deg, pitch_deg, yaw_deg)
    msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = x, y, z, w
    # A still accelerometer measures the reaction to gravity: +g along the world's up axis,
    # expressed in the sensor frame (m/s²).
    roll, pitch = math.radians(roll_deg), math.radians(pitch_deg)
    msg.linear_acceleration.x = -GRAVITY * math.sin(pitch)
    msg.linear_acceleration.y = GRAVITY * math.sin(roll) * math.cos(pitch)
    msg.linear_acceleration.z = GRAVITY * math.cos(roll) * math.cos(pitch)
    return msg


def message_size(msg) -> int:
    """Bytes of ``msg`` on the wire: its CDR serialization, as DDS sends it (payload only)."""
    return len(serialize_message(msg))


class TemperatureSensor(Node):
    """Publishes a temperature in °C that follows a sine wave (std_msgs/Float64)."""

    def __init__(self, name: str = "temperature_sensor", topic: str = "sensor/temperature",
                 rate_hz: float = 10.0, mean_c: float = 25.0, amplitude_c: float = 5.0,
                 period_s: float = 10.0, namespace: str = ""):
        super().__init__(name, namespace=namespace)
        self.mean_c, self.amplitude_c, self.period_s = mean_c, amplitude_c, period_s
        self.start = time.monotonic()
        self.publisher = self.create_publisher(Float64, topic, 10)
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)  # period in seconds

    def tick(self) -> None:
        t = time.monotonic() - self.start  # seconds since start
        celsius = self.mean_c + self.amplitude_c * math.sin(2 * math.pi * t / self.period_s)
        self.publisher.publish(Float64(data=celsius))


def make_temperature_sensor(name: str = "temperature_sensor", mean_c: float = 25.0,
                            amplitude_c: float = 5.0, rate_hz: float = 10.0,
                            topic: str = "sensor/temperature") -> Node:
    """Child-process target: a :class:`TemperatureSensor` (several can share one topic)."""
    return TemperatureSensor(name=name, topic=topic, rate_hz=rate_hz, mean_c=mean_c,
                             amplitude_c=amplitude_c)


class CmdVelPublisher(Node):
    """Drives forward at a constant speed while turning gently left and right (geometry_msgs/Twist)."""

    def __init__(self, name: str = "teleop", topic: str = "cmd_vel", rate_hz: float = 10.0,
                 speed_mps: float = 0.5, turn_radps: float = 0.3, namespace: str = ""):
        super().__init__(name, namespace=namespace)
        self.speed_mps, self.turn_radps = speed_mps, turn_radps
        self.start = time.monotonic()
        self.publisher = self.create_publisher(Twist, topic, 10)
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)

    def tick(self) -> None:
        t = time.monotonic() - self.start
        msg = Twist()
        msg.linear.x = self.speed_mps  # forward, m/s
        msg.angular.z = self.turn_radps * math.sin(t)  # yaw rate, rad/s (positive: turn left)
        self.publisher.publish(msg)


class ImuPublisher(Node):
    """Publishes the attitude of a robot at rest (sensor_msgs/Imu); ``set_tilt`` changes it live."""

    def __init__(self, name: str = "imu_driver", topic: str = "imu", rate_hz: float = 20.0,
                 roll_deg: float = 0.0, pitch_deg: float = 0.0, namespace: str = ""):
        super().__init__(name, namespace=namespace)
        self.roll_deg, self.pitch_deg = roll_deg, pitch_deg
        self.sent = 0
        self.publisher = self.create_publisher(Imu, topic, 10)
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)

    def set_tilt(self, roll_deg: float = 0.0, pitch_deg: float = 0.0) -> None:
        """Tilt the simulated robot: roll about its x axis, pitch about its y axis (degrees)."""
        self.roll_deg, self.pitch_deg = float(roll_deg), float(pitch_deg)

    def tick(self) -> None:
        msg = imu_message(self.roll_deg, self.pitch_deg)
        msg.header.stamp = self.get_clock().now().to_msg()
        self.publisher.publish(msg)
        self.sent += 1


# ---------------------------------------------------------------------- the throughput exercise
class ImuSensor(Node):
    """One IMU of a sensor array: an Imu message on ``~/data`` at ``rate_hz`` (counts what it sent)."""

    def __init__(self, name: str, rate_hz: float = 100.0, namespace: str = "sensors"):
        super().__init__(name, namespace=namespace)
        self.sent = 0
        self.template = imu_message(frame_id=name)
        self.publisher = self.create_publisher(Imu, "~/data", 10)  # e.g. /sensors/imu_3/data
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)

    def tick(self) -> None:
        self.template.header.stamp = self.get_clock().now().to_msg()
        self.publisher.publish(self.template)
        self.sent += 1


SENT_COUNT_SERVICE = "/sensor_array/sent_count"


def sensor_topics(count: int = 10, namespace: str = "sensors") -> list[str]:
    """The topics of :func:`make_sensor_array`: ``/sensors/imu_0/data`` ... (sorted by index)."""
    return [f"/{namespace.strip('/')}/imu_{i}/data" for i in range(count)]


def make_sensor_array(count: int = 10, rate_hz: float = 100.0, namespace: str = "sensors") -> list[Node]:
    """Child-process target: ``count`` IMU nodes publishing at ``rate_hz`` each, and a bookkeeper.

    The bookkeeper node ``/sensor_array`` answers the ``std_srvs/srv/Trigger`` service
    ``/sensor_array/sent_count`` with the total number of messages published so far (in
    ``response.message``): the ground truth a checker compares a measurement with.
    """
    if not 1 <= int(count) <= 50:
        raise CourseError(f"count must be 1..50 sensors, got {count!r}")
    if not 0 < float(rate_hz) <= 1000:
        raise CourseError(f"rate_hz must be in (0, 1000], got {rate_hz!r}")
    sensors = [ImuSensor(f"imu_{i}", rate_hz, namespace) for i in range(int(count))]
    bookkeeper = Node("sensor_array")

    def report(_request, response):
        response.success = True
        response.message = str(sum(s.sent for s in sensors))
        return response

    bookkeeper.sent_service = bookkeeper.create_service(Trigger, SENT_COUNT_SERVICE, report)
    return [*sensors, bookkeeper]


def sent_count(node: Node, timeout: float = 5.0) -> tuple[int, float]:
    """Ask the sensor array how many messages it has sent; return (count, monotonic time of answer).

    ``node`` must be spun by an executor (a node added with ``rt.add`` or ``rt.node``).
    """
    from course_helpers.core.runtime import get_runtime

    rt = get_runtime()
    client = node.create_client(Trigger, SENT_COUNT_SERVICE)
    try:
        if not client.wait_for_service(timeout_sec=timeout):
            raise CourseError(f"no sensor array answers {SENT_COUNT_SERVICE}; start it with "
                              "rt.spawn('sensors', 'course_helpers.chapters.ch03_topics:make_sensor_array')")
        sent_at = time.monotonic()
        response = rt.wait_for_future(client.call_async(Trigger.Request()), timeout,
                                      SENT_COUNT_SERVICE)
        received_at = time.monotonic()
        return int(response.message), (sent_at + received_at) / 2
    finally:
        rt.call_in_executor(node.destroy_client, client)


# ---------------------------------------------------------------------- message size vs rate
class PayloadPublisher(Node):
    """Publishes ``size_bytes`` of payload (std_msgs/UInt8MultiArray) on ``topic`` at ``rate_hz``."""

    def __init__(self, size_bytes: int, rate_hz: float, topic: str = "payload",
                 name: str = "payload_publisher"):
        super().__init__(name)
        self.msg = UInt8MultiArray()
        self.msg.data = bytes(size_bytes)
        self.publisher = self.create_publisher(UInt8MultiArray, topic, 10)
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)

    def tick(self) -> None:
        self.publisher.publish(self.msg)


def make_payload_publisher(size_bytes: int = 1000, rate_hz: float = 100.0,
                           topic: str = "payload") -> Node:
    """Child-process target: a :class:`PayloadPublisher`."""
    return PayloadPublisher(int(size_bytes), float(rate_hz), topic)


@dataclass
class BandwidthSample:
    """What a subscriber received from one payload size during the measurement window."""

    payload_bytes: int
    wire_bytes: int  # serialized size of one message
    nominal_hz: float
    received_hz: float
    bytes_per_s: float

    @property
    def computed_bytes_per_s(self) -> float:
        """What the bandwidth should be: nominal rate x message size."""
        return self.nominal_hz * self.wire_bytes


def measure_bandwidth(rt, sizes=(100, 10_000, 100_000, 500_000), rate_hz: float = 50.0,
                      duration_s: float = 1.0) -> list[BandwidthSample]:
    """For each payload size, run a publisher in a child process and measure what arrives here.

    The subscriber takes messages raw (serialized bytes, like ``ros2 topic bw``), so it counts
    exactly what travelled through the middleware.
    """
    sizes = [int(s) for s in sizes]
    if not sizes or any(s < 0 or s > 4_000_000 for s in sizes):
        raise CourseError(f"sizes must be payload sizes from 0 to 4000000 bytes, got {sizes!r}")
    if not 0 < rate_hz <= 500:
        raise CourseError(f"rate_hz must be in (0, 500], got {rate_hz!r}")
    meter = rt.node("bandwidth_meter", console=False)
    samples = []
    received: list[int] = []
    subscription = meter.create_subscription(UInt8MultiArray, "/payload",
                                             lambda raw: received.append(len(raw)), 10, raw=True)
    try:
        for size in sizes:
            wire = message_size(_payload(size))

            def this_size(n: int, wire: int = wire) -> bool:
                # a late message of the previous (stopped) publisher must not count for this size
                return wire / 2 <= n <= wire * 2 + 64

            rt.spawn("payload", "course_helpers.chapters.ch03_topics:make_payload_publisher",
                     {"size_bytes": size, "rate_hz": rate_hz}, wait_for="/payload_publisher")
            rt.wait_until(lambda: sum(map(this_size, received)) >= 2, 10, f"the first {size}-byte messages")
            start_count, start = len(received), time.monotonic()
            time.sleep(duration_s)
            window = [n for n in received[start_count:] if this_size(n)]
            elapsed = time.monotonic() - start
            samples.append(BandwidthSample(size, wire, rate_hz, len(window) / elapsed,
                                           sum(window) / elapsed))
            rt.stop_child("payload")
            received.clear()
    finally:
        rt.stop_child("payload")
        rt.call_in_executor(meter.destroy_subscription, subscription)
        rt.remove(meter)
    return samples


def _payload(size: int) -> UInt8MultiArray:
    msg = UInt8MultiArray()
    msg.data = bytes(size)
    return msg


def plot_bandwidth(samples: list[BandwidthSample]):
    """Bar chart: measured vs computed bandwidth per message size, with the received rate on top."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.8))
    labels = [_human_bytes(s.wire_bytes) for s in samples]
    xs = range(len(samples))
    ax.bar([x - 0.2 for x in xs], [s.computed_bytes_per_s / 1e6 for s in samples], width=0.4,
           label="computed: rate × size", color="#cbd5e1", edgecolor="#475569")
    ax.bar([x + 0.2 for x in xs], [s.bytes_per_s / 1e6 for s in samples], width=0.4,
           label="measured at the subscriber", color="#60a5fa", edgecolor="#1d4ed8")
    for x, s in zip(xs, samples, strict=True):
        ax.annotate(f"{s.received_hz:.0f} Hz", (x + 0.2, s.bytes_per_s / 1e6), ha="center",
                    va="bottom", fontsize=8, xytext=(0, 2), textcoords="offset points")
    ax.set_yscale("log")
    ax.set_xticks(list(xs), labels)
    ax.set_xlabel(f"message size on the wire (published at {samples[0].nominal_hz:g} Hz)")
    ax.set_ylabel("bandwidth (MB/s, log scale)")
    ax.set_title("Same rate, bigger messages: bandwidth grows with size")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    return fig


def _human_bytes(n: float) -> str:
    for unit in ("B", "kB", "MB"):
        if n < 1000 or unit == "MB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} MB"
