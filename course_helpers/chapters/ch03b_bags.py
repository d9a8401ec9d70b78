"""Chapter 03b, recording and replay: a robot's odometry to record, and plots of what a bag holds.

* :class:`OdometrySource` - a wheel-odometry driver, run in a child process: it measures the
  robot's pose 20 times a second and stamps each measurement with the time it was taken, but hands
  it over a little later (5 to 40 ms, like a driver that reads a serial bus), and for a while it
  stops altogether (a loose cable), so a bag of it has both things a node must cope with;
* :func:`record_odometry` - records a run of it into a bag;
* :func:`plot_speeds` - speeds computed from the header stamps and from the receive times.
"""

from __future__ import annotations

import random
from collections import deque

from nav_msgs.msg import Odometry
from rclpy.node import Node

from course_helpers.core.channel import report

PERIOD_S = 0.05  # s between two measurements (20 Hz)
LATENCY_S = (0.005, 0.040)  # s from measuring to publishing, drawn per message
DROPOUT_S = (3.0, 4.2)  # s after the start: no odometry at all (the cable is loose)
RUN_S = 6.0  # s the driver measures, then it stops


def speed_at(t: float) -> float:
    """The robot's true speed [m/s] ``t`` seconds after the start: it speeds up from 0.2 to 0.8 m/s."""
    return 0.2 + 0.6 * min(t / RUN_S, 1.0)


def distance_at(t: float) -> float:
    """How far [m] the robot has driven ``t`` seconds after the start (the integral of speed_at)."""
    t = min(t, RUN_S)
    return 0.2 * t + 0.3 * t * t / RUN_S


class OdometrySource(Node):
    """Publishes ``odom`` (nav_msgs/Odometry): the robot drives along x, speeding up; each message is
    stamped when measured and published 5-40 ms later; none is published during ``DROPOUT_S``."""

    def __init__(self, seed: int = 3):
        super().__init__("wheel_odometry")
        self.random = random.Random(seed)
        self.publisher = self.create_publisher(Odometry, "odom", 10)
        self.started = self.get_clock().now()
        self.waiting: deque = deque()  # (due in ns, message), in order
        self.measure_timer = self.create_timer(PERIOD_S, self.measure)
        self.send_timer = self.create_timer(0.002, self.send)  # hands over what is due [every 2 ms]

    def measure(self) -> None:
        now = self.get_clock().now()
        t = (now - self.started).nanoseconds / 1e9
        if t > RUN_S:
            self.measure_timer.cancel()
            report("done")  # to the kernel, over the process channel
            return
        if DROPOUT_S[0] <= t < DROPOUT_S[1]:
            return
        msg = Odometry()
        msg.header.stamp = now.to_msg()  # when the pose was measured
        msg.header.frame_id, msg.child_frame_id = "odom", "base_link"
        msg.pose.pose.position.x = distance_at(t)
        msg.pose.pose.orientation.w = 1.0
        msg.twist.twist.linear.x = speed_at(t)
        due = now.nanoseconds + round(self.random.uniform(*LATENCY_S) * 1e9)
        self.waiting.append((due, msg))

    def send(self) -> None:
        now = self.get_clock().now().nanoseconds
        while self.waiting and self.waiting[0][0] <= now:
            self.publisher.publish(self.waiting.popleft()[1])


def record_odometry(rt, output: str, overwrite: bool = False):
    """Run :class:`OdometrySource` in a child process and record its ``/odom`` into the bag
    ``output``, from before its first message to after its last; returns the bag's info."""
    from course_helpers.core import bags

    recording = bags.record(rt, output, ["/odom"], overwrite=overwrite)
    child = rt.spawn("wheel_odometry", OdometrySource, wait_for="/wheel_odometry")
    rt.wait_until(lambda: "/odom" in recording.topics, 10, "the recorder to subscribe to /odom")
    child.wait_for_report("done", RUN_S + 10.0)  # the whole run
    rt.stop_child("wheel_odometry")
    recording.stop()
    return bags.bag_info(output)


def speeds(stamped: list[tuple[float, float]]) -> list[float]:
    """Speeds [m/s] between consecutive ``(time s, x m)`` points."""
    return [(x1 - x0) / (t1 - t0) for (t0, x0), (t1, x1) in zip(stamped, stamped[1:], strict=False)]


def plot_speeds(messages: list[tuple[int, Odometry]]):
    """Speed from the header stamps against speed from the receive times, for a bag's ``/odom``
    (``bags.read(bag, '/odom')``); returns the figure."""
    import matplotlib.pyplot as plt

    start = messages[0][0]
    received = [((t - start) / 1e9, m.pose.pose.position.x) for t, m in messages]
    stamped = [((m.header.stamp.sec * 10**9 + m.header.stamp.nanosec - start) / 1e9, m.pose.pose.position.x)
               for t, m in messages]
    fig, ax = plt.subplots(figsize=(8, 3.2))
    ax.plot([t for t, _ in received[1:]], speeds(received), ".", color="tab:red", label="from receive times")
    ax.plot([t for t, _ in stamped[1:]], speeds(stamped), "-", color="tab:blue", label="from header stamps")
    ax.set_xlabel("time since the first message [s]")
    ax.set_ylabel("speed [m/s]")
    ax.legend(loc="upper left")
    ax.set_title("The same bag, two clocks")
    fig.tight_layout()
    return fig
