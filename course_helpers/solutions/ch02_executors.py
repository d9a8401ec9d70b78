"""Reference solution of chapter 02 (nodes and executors); CI checks it with ``checks.ch02_executors``."""

from __future__ import annotations

import time

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node


class Robot(Node):
    """Exercise 02: the heartbeat in a callback group of its own, the two slow callbacks in another."""

    def __init__(self):
        super().__init__('robot')
        self.beats, self.frames, self.plans = [], 0, 0
        # The heartbeat never waits for a slow callback: it has a group of its own. The camera and
        # the planner share one group, so they never run at the same time (they might share hardware).
        beat_group = MutuallyExclusiveCallbackGroup()
        slow_group = MutuallyExclusiveCallbackGroup()
        self.heartbeat_timer = self.create_timer(0.1, self.heartbeat, callback_group=beat_group)
        self.camera_timer = self.create_timer(0.2, self.camera, callback_group=slow_group)
        self.planner_timer = self.create_timer(0.5, self.planner, callback_group=slow_group)

    def heartbeat(self):
        self.beats.append(time.monotonic())

    def camera(self):
        time.sleep(0.05)  # waiting for a frame
        self.frames += 1

    def planner(self):
        time.sleep(0.3)  # a slow, blocking computation
        self.plans += 1
