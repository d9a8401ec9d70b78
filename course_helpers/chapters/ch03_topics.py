"""Sensor and command nodes of chapter 03 (topics), in the kernel or in child processes.

* :class:`TemperatureSensor` - ``std_msgs/msg/Float64`` on ``sensor/temperature``, a sine wave in °C
  (``rt.spawn('thermo', TemperatureSensor, {'name': 'thermo'})`` runs one in a child process);
* :class:`CmdVelPublisher` - ``geometry_msgs/msg/Twist`` on ``cmd_vel`` (m/s, rad/s);
* :class:`ImuPublisher` - ``sensor_msgs/msg/Imu`` on ``imu`` with a tilt you can set;
* :func:`make_sensor_array` - N IMU nodes at R Hz (the throughput exercise), and a node that
  reports over the process channel how many messages they really sent (:func:`sent_rate` reads it);
  :class:`ArrayListener` counts what arrives from all of them in the kernel;
* :func:`measure_bandwidth` / :func:`plot_bandwidth` - the message-size-versus-rate demo.

Every node is written the way a student would write it: a Node subclass, a timer instead of a sleep
loop, units in comments.
"""

from __future__ import annotations

import math
import time
from array import array
from dataclasses import dataclass

from geometry_msgs.msg import Twist
from rclpy.node import Node
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Imu
from std_msgs.msg import Float64, UInt8MultiArray

from course_helpers.core.channel import report
from course_helpers.core.errors import CourseError
from course_helpers.core.executors import spinning_alone
from course_helpers.core.names import full_name
from course_helpers.core.units import format_bytes
from course_helpers.core.waiting import wait_until

GRAVITY = 9.80665  # m/s²


def quaternion_from_rpy(roll_deg: float, pitch_deg: float, yaw_deg: float = 0.0):
    """Return the unit quaternion ``(x, y, z, w)`` of a roll-pitch-yaw rotation given in degrees.

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
    """An Imu message of a robot standing still with this attitude (degrees): its orientation, and
    gravity as a still accelerometer measures it; the header's ``frame_id`` is ``frame_id``."""
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
    """Bytes of ``msg`` (any ROS message) on the wire: its CDR serialization, as DDS sends it
    (payload only)."""
    return len(serialize_message(msg))


class TemperatureSensor(Node):
    """Publishes a temperature in °C that follows a sine wave (std_msgs/Float64) on ``topic``.

    ``mean_c ± amplitude_c`` with a period of ``period_s`` seconds, ``rate_hz`` messages a second.
    Several sensors may share one topic.
    """

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
    """One IMU of a sensor array: an Imu message on ``~/data`` at ``rate_hz``; ``sent`` counts them."""

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


SENT_REPORT_PERIOD_S = 0.1  # how often the sensor array reports its count on the channel


class SentCounter(Node):
    """The bookkeeper of a sensor array: reports the messages its ``sensors`` sent, over the channel.

    Every ``period_s`` seconds it sends ``report('sent', count=N)`` to the kernel: the ground
    truth that :func:`sent_rate` turns into messages per second.
    """

    def __init__(self, sensors: list[ImuSensor], name: str = "sensor_array",
                 period_s: float = SENT_REPORT_PERIOD_S):
        super().__init__(name)
        self.sensors = sensors
        self.timer = self.create_timer(period_s, self.report_count)

    def report_count(self) -> None:
        report("sent", count=sum(sensor.sent for sensor in self.sensors))


class ArrayListener(Node):
    """Subscribes (raw) to every topic in ``topics`` (sensor_msgs/Imu) and counts what arrives.

    ``messages`` and ``bytes`` grow with every message (serialised size, like ``ros2 topic bw``);
    the notebook reads them before and after a listening window.
    """

    def __init__(self, topics: list[str], name: str = "load_meter"):
        super().__init__(name)
        self.messages = 0
        self.bytes = 0
        self.array_subscriptions = [self.create_subscription(Imu, topic, self.on_message, 100, raw=True)
                                    for topic in topics]

    def on_message(self, raw: bytes) -> None:
        self.messages += 1
        self.bytes += len(raw)


def sensor_topics(count: int = 10, namespace: str = "sensors") -> list[str]:
    """The topics of :func:`make_sensor_array`: ``['/sensors/imu_0/data', ...]``, sorted by index."""
    return [full_name("/" + namespace.strip("/"), f"imu_{i}/data") for i in range(count)]


def make_sensor_array(count: int = 10, rate_hz: float = 100.0, namespace: str = "sensors") -> list[Node]:
    """Child-process target: ``count`` :class:`ImuSensor` nodes at ``rate_hz`` each, and a bookkeeper.

    Returns the sensors and the :class:`SentCounter` ``/sensor_array``, which reports their total
    count over the channel (read it with :func:`sent_rate`).
    """
    if not 1 <= int(count) <= 50:
        raise CourseError(f"count must be 1..50 sensors, got {count!r}")
    if not 0 < float(rate_hz) <= 1000:
        raise CourseError(f"rate_hz must be in (0, 1000], got {rate_hz!r}")
    sensors = [ImuSensor(f"imu_{i}", rate_hz, namespace) for i in range(int(count))]
    return [*sensors, SentCounter(sensors)]


def sent_rate(child, start: float, end: float, timeout: float = 5.0) -> float:
    """Messages per second a child process published between two ``time.monotonic()`` instants.

    Args:
        child: the ChildProcess of :func:`make_sensor_array` or :class:`PayloadPublisher`; it
            reports ``report('sent', count=N)`` on its channel.
        start, end: the measurement window (this machine's monotonic clock, seconds).
        timeout: seconds to wait for the child's first count after ``end``.

    Returns:
        The rate between the child's last count before ``start`` (or its first one) and its first
        count after ``end``.
    """
    wait_until(lambda: any(t >= end for t, _ in child.channel.stamped("sent")) or not child.alive,
               timeout, f"the message count of {child.label!r} after the measurement")
    counts = child.channel.stamped("sent")
    after = next(((t, d) for t, d in counts if t >= end), None)
    if after is None:
        raise child.failure("it reported its message count")
    before = max(((t, d) for t, d in counts if t <= start), default=counts[0], key=lambda c: c[0])
    return (after[1]["count"] - before[1]["count"]) / (after[0] - before[0])


# ---------------------------------------------------------------------- message size vs rate
def payload_message(size_bytes: int) -> UInt8MultiArray:
    """A std_msgs/UInt8MultiArray carrying ``size_bytes`` zero bytes."""
    msg = UInt8MultiArray()
    msg.data = bytes(size_bytes)
    return msg


NUMBER_BYTES = 8  # each payload starts with its message's number (little-endian), so sent and received match
CDR_DATA_OFFSET = 16  # where a serialized UInt8MultiArray's data begins: CDR header, empty layout, length


class PayloadPublisher(Node):
    """Publishes ``size_bytes`` of payload (std_msgs/UInt8MultiArray) on ``topic`` at ``rate_hz``; the
    payload's first 8 bytes hold the message's number (1, 2, ...).

    After each message it reports ``report('sent', count=N)`` over the process channel (in a child
    process; see :func:`sent_rate`): N is also the number of the message just sent.
    """

    def __init__(self, size_bytes: int, rate_hz: float, topic: str = "payload",
                 name: str = "payload_publisher"):
        super().__init__(name)
        self.msg = payload_message(max(size_bytes, NUMBER_BYTES))
        self.sent = 0
        self.publisher = self.create_publisher(UInt8MultiArray, topic, 10)
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)

    def tick(self) -> None:
        self.sent += 1
        self.msg.data[:NUMBER_BYTES] = array("B", self.sent.to_bytes(NUMBER_BYTES, "little"))
        self.publisher.publish(self.msg)
        report("sent", count=self.sent)


class BandwidthMeter(Node):
    """Keeps the number and the size in bytes of every message on ``topic``, as it travelled (like
    ``ros2 topic bw``; a :class:`PayloadPublisher`'s messages carry their numbers).

    The subscription is raw: the callback gets the serialized message, not a decoded one.
    """

    def __init__(self, topic: str = "/payload", name: str = "bandwidth_meter"):
        super().__init__(name)
        self.sizes: list[int] = []  # bytes of each message received, oldest first
        self.numbers: list[int] = []  # the number each of them carried
        self.subscription = self.create_subscription(UInt8MultiArray, topic, self.on_message, 10, raw=True)

    def on_message(self, raw: bytes) -> None:
        number = raw[CDR_DATA_OFFSET:CDR_DATA_OFFSET + NUMBER_BYTES]
        self.numbers.append(int.from_bytes(number, "little"))
        self.sizes.append(len(raw))


@dataclass
class BandwidthSample:
    """What a subscriber received of the messages one payload size sent during the measurement window."""

    payload_bytes: int
    wire_bytes: int  # serialized size of one message
    nominal_hz: float
    received_hz: float  # of the messages sent in the window, those that arrived, per second
    bytes_per_s: float
    sent_hz: float  # what the publisher managed to send (less than nominal on a busy machine)

    @property
    def computed_bytes_per_s(self) -> float:
        """What the bandwidth should be: nominal rate x message size."""
        return self.nominal_hz * self.wire_bytes


def measure_bandwidth(rt, sizes=(100, 10_000, 100_000, 500_000), rate_hz: float = 50.0,
                      duration_s: float = 1.0) -> list[BandwidthSample]:
    """For each payload size, run a publisher in a child process and measure what arrives here.

    Args:
        rt: the kernel's course runtime.
        sizes: payload sizes in bytes (8..4,000,000: each message carries its 8-byte number),
            measured one after the other.
        rate_hz: the publishing rate, (0, 500] Hz.
        duration_s: the measurement window per size, seconds.

    Returns:
        One :class:`BandwidthSample` per size: of the messages the publisher sent in the window (its
        own reports say which), how many arrived and their bytes, per second of the window; so fewer
        can arrive than were sent, never more. A :class:`BandwidthMeter` in this process counts them,
        spun by an executor of its own so that the notebook's other nodes do not delay it.
    """
    sizes = [int(s) for s in sizes]
    if not sizes or any(s < NUMBER_BYTES or s > 4_000_000 for s in sizes):
        raise CourseError(f"sizes must be payload sizes from {NUMBER_BYTES} to 4000000 bytes (each message "
                          f"carries its {NUMBER_BYTES}-byte number), got {sizes!r}")
    if not 0 < rate_hz <= 500:
        raise CourseError(f"rate_hz must be in (0, 500], got {rate_hz!r}")
    samples = []
    # The meter spins alone: the notebook's other nodes cannot delay it.
    with spinning_alone(rt, BandwidthMeter, thread_name="bandwidth_meter") as meter:
        try:
            for size in sizes:
                samples.append(_measure_one_size(rt, meter, size, rate_hz, duration_s))
                rt.stop_child("payload")
                meter.sizes.clear()
                meter.numbers.clear()
        finally:
            rt.stop_child("payload")
    return samples


def _measure_one_size(rt, meter: BandwidthMeter, size: int, rate_hz: float,
                      duration_s: float) -> BandwidthSample:
    publisher = rt.spawn("payload", PayloadPublisher, {"size_bytes": size, "rate_hz": rate_hz},
                         wait_for="/payload_publisher")
    rt.wait_until(lambda: len(meter.numbers) >= 2, 10, f"the first {size}-byte messages")
    start = time.monotonic()
    time.sleep(duration_s)  # the measurement window
    end = time.monotonic()
    sent = {d["count"] for t, d in publisher.channel.stamped("sent") if start <= t <= end}
    last = max(sent, default=0)
    # a sentinel, not a wait: the next message, from the same writer in order, comes after them all
    rt.wait_until(lambda: any(n > last for n in meter.numbers[:]), 10, f"message {last + 1} of {size} bytes")
    wire = message_size(payload_message(size))  # a late message of the previous size is not one of these
    arrived = [b for n, b in zip(meter.numbers[:], meter.sizes[:], strict=False) if n in sent and b == wire]
    return BandwidthSample(size, wire, rate_hz, len(arrived) / (end - start),
                           sum(arrived) / (end - start), len(sent) / (end - start))


def plot_bandwidth(samples: list[BandwidthSample]):
    """Bar chart of :class:`BandwidthSample` s: measured vs computed bandwidth per payload size,
    with the received rate on top. Returns the matplotlib figure."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.8))
    labels = [format_bytes(s.payload_bytes, binary=False) for s in samples]
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
    ax.set_xlabel(f"payload per message (published at {samples[0].nominal_hz:g} Hz)")
    ax.set_ylabel("bandwidth (MB/s, log scale)")
    ax.set_title("Same rate, bigger messages: bandwidth grows with size")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    return fig
