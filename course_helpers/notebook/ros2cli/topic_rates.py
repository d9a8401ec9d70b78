"""``%ros2 topic hz`` and ``%ros2 topic bw``: rate and bandwidth of a topic, measured like ros2cli."""

from __future__ import annotations

import collections
import math
import threading
import time
from collections.abc import Callable

from rclpy.node import Node

from course_helpers.core.waiting import poll_until
from course_helpers.notebook.ros2cli._common import _TICK_S, _topic_arg
from course_helpers.notebook.ros2cli.topic_graph import (
    choose_subscription_qos,
    discover_type,
    message_class,
    print_warning,
    temporary_node,
    watch_events,
)

HZ_DEFAULT_S = 5.0  # topic hz and topic bw measure this long by default


class RateMeter:
    """ros2cli's ``topic hz`` statistics over arrival times taken in the executor thread."""

    def __init__(self, window: int):
        self.window = window
        self.lock = threading.Lock()
        self.times: list[int] = []  # intervals between messages, ns
        self.last_ns = -1
        self.last_printed_ns = 0
        self.received = 0

    def on_message(self, _raw) -> None:
        now = time.monotonic_ns()
        with self.lock:
            self.received += 1
            if self.last_ns >= 0:
                self.times.append(now - self.last_ns)
                if len(self.times) > self.window:
                    self.times.pop(0)
            self.last_ns = now

    def report(self) -> str | None:
        """A report once per second of message time, as ros2cli prints it (None: nothing new)."""
        with self.lock:
            if not self.times:
                return None
            if self.last_printed_ns == 0:
                self.last_printed_ns = self.last_ns
                return None
            if self.last_ns < self.last_printed_ns + 1_000_000_000:
                return None
            n = len(self.times)
            mean = sum(self.times) / n
            rate = 1e9 / mean if mean > 0 else 0.0
            std_dev = math.sqrt(sum((x - mean) ** 2 for x in self.times) / n)
            self.last_printed_ns = self.last_ns
            low, high = min(self.times), max(self.times)
        return (f"average rate: {rate:.3f}\n\tmin: {low * 1e-9:.3f}s max: {high * 1e-9:.3f}s "
                f"std dev: {std_dev * 1e-9:.5f}s window: {n}")


def topic_hz(rt, args):
    return _run_meter(rt, args, "hz", RateMeter(args.window))


class BandwidthMeter:
    """ros2cli's ``topic bw`` statistics: serialized sizes over a window of messages."""

    def __init__(self, window: int):
        self.window = window
        self.lock = threading.Lock()
        self.samples: collections.deque = collections.deque(maxlen=window)  # (time s, bytes)
        self.received = 0
        self.next_report = time.monotonic() + 1.0

    def on_message(self, raw: bytes) -> None:
        with self.lock:
            self.received += 1
            self.samples.append((time.monotonic(), len(raw)))

    def report(self) -> str | None:
        now = time.monotonic()
        if now < self.next_report:
            return None
        self.next_report += 1.0
        with self.lock:
            if len(self.samples) < 2 or now <= self.samples[0][0]:
                return None
            sizes = [size for _, size in self.samples]
            rate = sum(sizes) / (now - self.samples[0][0])
        unit, scale, digits = ("B", 1, 0) if rate < 1000 else ("KB", 1e3, 2) if rate < 1e6 else ("MB", 1e6, 2)

        def fmt(value):
            return f"{value / scale:.{digits}f} {unit}"

        return (f"{fmt(rate)}/s from {len(sizes)} messages\n\tMessage size mean: "
                f"{fmt(sum(sizes) / len(sizes))} min: {fmt(min(sizes))} max: {fmt(max(sizes))}")


def topic_bw(rt, args):
    return _run_meter(rt, args, "bw", BandwidthMeter(args.window), announce=True)


def _run_meter(rt, args, verb: str, meter, announce: bool = False):
    """Subscribe with ros2cli's QoS choice, feed raw messages to ``meter``, print its reports."""
    topic = _topic_arg(args.topic_name)
    msg_class = message_class(discover_type(rt, topic, verb))
    qos = choose_subscription_qos(rt, topic, args)
    duration = args.duration or HZ_DEFAULT_S
    warnings: collections.deque = collections.deque()
    with temporary_node(rt, verb) as node:
        node.create_subscription(msg_class, topic, meter.on_message, qos, raw=True,
                                 event_callbacks=watch_events(warnings))
        if announce:
            print(f"Subscribed to [{topic}]")
            meter.next_report = time.monotonic() + 1.0
        measure(duration, meter.report, lambda: print_warnings(node, topic, warnings))
    if meter.received == 0:
        print(f"(no message received on {topic} within {duration:g} s)")
    return None


def print_warnings(node: Node, topic: str, warnings: collections.deque) -> None:
    while warnings:
        print_warning(node, topic, warnings.popleft()[1])


def measure(duration: float, report: Callable[[], str | None], news: Callable[[], None]) -> None:
    """For ``duration`` seconds, print warnings (``news``) and every report as it becomes due."""
    def step() -> bool:
        news()
        text = report()
        if text:
            print(text)
        return False  # measure for the whole duration

    poll_until(step, duration, period=_TICK_S)
