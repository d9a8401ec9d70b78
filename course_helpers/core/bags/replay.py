"""A bag replayed into nodes under a :class:`~course_helpers.core.sim_clock.SimClock`: exactly.

``ros2 bag play --clock`` lives in the wall clock: how far the nodes got when a message arrives
depends on the machine's load. A checker, or a debugging session that must give the same output
run after run, replays instead with the clock and the executor in its own hands: the clock moves
to each message's recorded time (in steps of at most ``step_s``, so the nodes' timers fire on
time), the message is published, and everything settles before the next one. The nodes see
the bag's own time, each message at its recorded instant, and nothing depends on the machine.
"""

from __future__ import annotations

from collections.abc import Callable

from rclpy.node import Node

from course_helpers.core.bags.qos import offer_for_playback
from course_helpers.core.bags.reader import bag_info, message_class_of, messages
from course_helpers.core.errors import CourseError

DEFAULT_STEP_S = 0.01  # s of ROS time per clock step between two messages


class SimReplay:
    """``SimReplay(clock, path, topics=None)`` publishes the bag's messages into the nodes ``clock``
    drives; :meth:`run` replays them in order. ``clock`` must not be past the bag's start."""

    def __init__(self, runtime, clock, path, topics: list[str] | None = None, remap: dict | None = None):
        self.info = bag_info(path)
        chosen = [self.info.topic(t) for t in topics] if topics else list(self.info.topics)
        self.topics = [t.name for t in chosen]
        self.remap = dict(remap or {})
        if clock.now_s * 1e9 > self.info.start_ns + 1_000:  # (1 µs: a float's rounding of the start)
            raise CourseError(f"the clock is at {clock.now_s:.3f} s, after the bag's start "
                              f"({self.info.start_ns / 1e9:.3f} s): make it with start_s at or before "
                              f"the bag's start")
        self.clock = clock
        self.node = runtime.build(Node, "rosbag2_player", enable_rosout=False, start_parameter_services=False)
        self.publishers = {t.name: self.node.create_publisher(message_class_of(t),
                                                              self.remap.get(t.name, t.name),
                                                              offer_for_playback(t.offered))
                           for t in chosen}
        clock.drive(self.node)
        self.published = 0

    def run(self, until_s: float | None = None, step_s: float = DEFAULT_STEP_S,
            after: Callable[[str, int], None] | None = None) -> int:
        """Replay every message (up to ``until_s`` of bag time, if given); ``after(topic, stamp_ns)``
        is called once each message has been handled. Returns how many messages were published."""
        self.clock.wait_matched()
        for topic, stamp, data in messages(self.info.path, self.topics):
            if until_s is not None and stamp > until_s * 1e9:
                break
            gap_s = (stamp - round(self.clock.now_s * 1e9)) / 1e9
            if gap_s > 0:
                self.clock.advance(gap_s, step_s=step_s)
            self.publishers[topic].publish(data)
            self.clock.settle()
            self.published += 1
            if after is not None:
                after(topic, stamp)
        return self.published

    def close(self) -> None:
        """Destroy the replay's node (the clock keeps driving the others)."""
        self.node.destroy_node()
