"""The nodes chapter 08a's exercise checkers run against the student's code.

* :class:`RobotCmdPublisher` - robot commands sent best effort (exercise 08.2, a subscriber to match);
* :class:`CameraDriver` and :class:`SlowConsumer` - a 30 Hz camera and a slow perception node (08.1);
* :class:`OdomSensor` - odometry at 10 Hz with an offered deadline, silent for a while (08.3, the
  deadline watchdog);
* :class:`ScheduledHeartbeat` - a MANUAL_BY_TOPIC heartbeat that stops asserting for a while (08.4,
  the liveliness monitor).

The last two run in a child process (``rt.spawn``) and follow a :class:`QuietSpell`: they report
``start`` once a subscription matched, ``quiet`` when they fall silent and ``resume`` when they
speak again, so the kernel knows when each happened (the channel stamps reports with the
machine's monotonic clock).
"""

from __future__ import annotations

import time

from nav_msgs.msg import Odometry
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import Image
from std_msgs.msg import String

from course_helpers.core.channel import report
from course_helpers.core.qos_dict import qos_from_dict

ROBOT_CMD_QOS = {"reliability": "best_effort", "durability": "volatile", "history": "keep_last", "depth": 5}
COMMANDS = ("forward", "backward", "stop")
CAMERA_RATE_HZ = 30.0
CONSUMER_WORK_S = 0.15  # the perception node's processing time per frame
ODOM_RATE_HZ = 10.0
# What the odometry driver offers: reliable, and at least one message every 0.2 s.
ODOM_QOS = {"reliability": "reliable", "depth": 10, "deadline_s": 0.2}
HEARTBEAT_PERIOD_S = 0.1  # s between the scheduled heartbeat's assertions
# What the scheduled heartbeat offers: its writer asserts itself within every 0.5 s lease.
HEARTBEAT_QOS = {"depth": 1, "liveliness": "manual_by_topic", "lease_s": 0.5}


class RobotCmdPublisher(Node):
    """Sends 'forward', 'backward', 'stop' in turn on /robot_cmd at ``rate_hz``, QoS :data:`ROBOT_CMD_QOS`."""

    def __init__(self, name: str = "robot_controller", rate_hz: float = 5.0):
        super().__init__(name)
        self.sent = 0
        self.publisher = self.create_publisher(String, "/robot_cmd", qos_from_dict(ROBOT_CMD_QOS))
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)  # period in seconds

    def tick(self) -> None:
        self.publisher.publish(String(data=COMMANDS[self.sent % len(COMMANDS)]))
        self.sent += 1


class CameraDriver(Node):
    """Publishes mono8 images of ``width`` x ``height`` at ``rate_hz``, stamped with the time they were
    taken, on camera/image_raw with the QoS given as a dict (a child-process target)."""

    def __init__(self, qos: dict, rate_hz: float = CAMERA_RATE_HZ, width: int = 640, height: int = 480):
        super().__init__("camera_driver")
        self.publisher = self.create_publisher(Image, "camera/image_raw", qos_from_dict(qos))
        self.frame = Image(height=height, width=width, encoding="mono8", step=width,
                           data=bytes(width * height))
        self.timer = self.create_timer(1.0 / rate_hz, self.capture)  # period in seconds

    def capture(self) -> None:
        self.frame.header.stamp = self.get_clock().now().to_msg()
        self.publisher.publish(self.frame)


class SlowConsumer(Node):
    """Takes :data:`CONSUMER_WORK_S` per camera frame and notes each frame's age when work starts.

    Ages (seconds from the frame's stamp) are kept in :attr:`ages` once ``warm_up`` seconds have
    passed since the first frame (the queue fills up meanwhile).
    """

    def __init__(self, qos: QoSProfile, warm_up: float):
        super().__init__("perception")
        self.warm_up = warm_up
        self.first_frame_at: float | None = None  # time.monotonic()
        self.ages: list[float] = []
        self.subscription = self.create_subscription(Image, "camera/image_raw", self.work, qos)

    def work(self, frame: Image) -> None:
        now = self.get_clock().now()
        if self.first_frame_at is None:
            self.first_frame_at = time.monotonic()
        if time.monotonic() - self.first_frame_at > self.warm_up:
            stamp_ns = frame.header.stamp.sec * 10**9 + frame.header.stamp.nanosec
            self.ages.append((now.nanoseconds - stamp_ns) / 1e9)
        time.sleep(CONSUMER_WORK_S)  # stands for the perception work; blocks like real work would

    def watched_for(self, seconds: float) -> bool:
        """True once ``warm_up`` + ``seconds`` have passed since the first frame."""
        started = self.first_frame_at
        return started is not None and time.monotonic() - started >= self.warm_up + seconds


class QuietSpell:
    """A schedule: speak for ``speak_s`` once started, stay silent for ``quiet_s``, speak again for
    ``after_s``, and keep speaking.

    :meth:`speaking` is asked on every tick; it reports ``quiet``, ``resume`` and ``done`` over the
    channel the first time each phase begins, so the kernel learns when the schedule's last phase
    ended from the schedule itself, instead of sleeping through it.
    """

    def __init__(self, speak_s: float, quiet_s: float, after_s: float = 1.0):
        self.speak_s, self.quiet_s, self.after_s = speak_s, quiet_s, after_s
        self.started_at: float | None = None  # time.monotonic()
        self.phase = "waiting"

    def start(self) -> None:
        """Begin the schedule now, and report ``start``."""
        self.started_at = time.monotonic()
        self.phase = "speaking"
        report("start")

    def speaking(self) -> bool:
        """True while the node should publish (or assert); False before :meth:`start` and while quiet."""
        if self.started_at is None:
            return False
        elapsed = time.monotonic() - self.started_at
        phase = ("speaking" if elapsed < self.speak_s else
                 "quiet" if elapsed < self.speak_s + self.quiet_s else
                 "resumed" if elapsed < self.speak_s + self.quiet_s + self.after_s else "done")
        if phase != self.phase:
            self.phase = phase
            report({"quiet": "quiet", "resumed": "resume", "done": "done"}[phase])
        return phase != "quiet"


class OdomSensor(Node):
    """An odometry driver: /odom at :data:`ODOM_RATE_HZ`, offering :data:`ODOM_QOS` (a 0.2 s deadline).

    It starts its :class:`QuietSpell` once a subscription matched, and is silent for ``quiet_s``
    after ``speak_s`` seconds (a child-process target).
    """

    def __init__(self, speak_s: float = 1.0, quiet_s: float = 1.6, after_s: float = 1.5):
        super().__init__("odom_driver")
        self.spell = QuietSpell(speak_s, quiet_s, after_s)
        self.publisher = self.create_publisher(Odometry, "/odom", qos_from_dict(ODOM_QOS))
        self.message = Odometry()
        self.message.header.frame_id = "odom"
        self.timer = self.create_timer(1.0 / ODOM_RATE_HZ, self.tick)  # period in seconds

    def tick(self) -> None:
        if self.spell.started_at is None and self.publisher.get_subscription_count() > 0:
            self.spell.start()
        if self.spell.speaking():
            self.message.header.stamp = self.get_clock().now().to_msg()
            self.publisher.publish(self.message)


class ScheduledHeartbeat(Node):
    """A heartbeat on /heartbeat with :data:`HEARTBEAT_QOS` that asserts its liveliness every
    :data:`HEARTBEAT_PERIOD_S`, and stops for ``quiet_s`` after ``speak_s`` (a child-process target)."""

    def __init__(self, speak_s: float = 1.0, quiet_s: float = 1.5, after_s: float = 1.0):
        super().__init__("heartbeat_driver")
        self.spell = QuietSpell(speak_s, quiet_s, after_s)
        self.publisher = self.create_publisher(String, "/heartbeat", qos_from_dict(HEARTBEAT_QOS))
        self.timer = self.create_timer(HEARTBEAT_PERIOD_S, self.tick)  # period in seconds

    def tick(self) -> None:
        if self.spell.started_at is None and self.publisher.get_subscription_count() > 0:
            self.spell.start()
        if self.spell.speaking():
            self.publisher.assert_liveliness()
