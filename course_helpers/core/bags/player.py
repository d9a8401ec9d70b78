"""Playing a bag: ``ros2 bag play`` in the kernel, in a thread of its own.

A :class:`Playback` publishes the bag's serialized messages as they are (``Publisher.publish``
of the bytes: nothing is deserialized), at the pace they were recorded, scaled by ``rate``.
Each topic is offered with the QoS its recording kept (:func:`.qos.offer_for_playback`, rosbag2's
rule), so a transient-local topic is replayed as transient-local. The pace comes from a
:class:`~course_helpers.core.clock_player.ClockPlayer` that starts at the bag's first timestamp:
with ``clock_hz`` it also publishes that time on ``/clock`` (``--clock``), so nodes with
``use_sim_time`` live in the bag's time. ``loop`` starts again from the beginning (the bag's
clock jumps back), until :meth:`Playback.stop`.
"""

from __future__ import annotations

import threading
from collections import Counter
from pathlib import Path

from rclpy.node import Node

from course_helpers.core.bags.qos import offer_for_playback
from course_helpers.core.bags.reader import bag_info, message_class_of, messages
from course_helpers.core.clock_player import ClockPlayer
from course_helpers.core.errors import CourseError

NODE_NAME = "rosbag2_player"
_playbacks: list[Playback] = []
_lock = threading.Lock()


class Playback:
    """One bag being played. ``wait()``, ``stop()``, ``pause()``, ``resume()``, ``set_rate()``;
    ``published`` counts the messages sent per topic; ``clock`` is the bag's time."""

    def __init__(self, rt, path, rate: float = 1.0, topics: list[str] | None = None, loop: bool = False,
                 clock_hz: float | None = None, delay_s: float = 0.0, start_paused: bool = False):
        self.info = bag_info(path)
        self.path: Path = self.info.path
        names = topics or [t.name for t in self.info.topics]
        self.topics = [self.info.topic(t).name for t in names]
        chosen = [self.info.topic(name) for name in self.topics]
        classes = {t.name: message_class_of(t) for t in chosen}  # an unknown type fails here, before anything
        if delay_s < 0:
            raise CourseError(f"delay must be >= 0 seconds, got {delay_s!r}")
        self.rt = rt.start()
        self.loop = loop
        self.delay_s = delay_s
        self.published: Counter = Counter()
        self.loops = 0
        self.error: BaseException | None = None
        self.clock = ClockPlayer(rt, start_s=self.info.start_ns / 1e9, rate=rate, publish_hz=clock_hz,
                                 name="_rosbag2_player_clock")
        self.clock.pause()  # held at the first message's time until the thread starts
        self.node = Node(NODE_NAME, context=rt.context, enable_rosout=False, start_parameter_services=False)
        self.publishers = {t.name: self.node.create_publisher(classes[t.name], t.name,
                                                              offer_for_playback(t.offered))
                           for t in chosen}
        self._start_paused = start_paused
        self._stop = threading.Event()
        self.finished = threading.Event()
        self._thread = threading.Thread(target=self._play, name=f"bag-play-{self.path.name}", daemon=True)
        self._thread.start()

    def _play(self) -> None:
        try:
            if self.delay_s and self._stop.wait(self.delay_s):
                return
            if not self._start_paused:
                self.clock.resume()
            while not self._stop.is_set():
                for topic, stamp, data in messages(self.path, self.topics):
                    if not self.clock.wait_until(stamp, self._stop):
                        return
                    self.publishers[topic].publish(data)
                    self.published[topic] += 1
                self.loops += 1
                if not self.loop:
                    return
                self.clock.jump(self.info.start_ns / 1e9)  # back to the start: a time jump under --clock
        except Exception as exc:  # a damaged bag found halfway: keep it for wait() to raise
            self.error = exc
        finally:
            self._finish()

    def _finish(self) -> None:
        if self.finished.is_set():
            return
        self.clock.close()
        node = self.node

        def destroy():
            node.destroy_node()

        if self.rt.running:
            self.rt.call_in_executor(destroy)
        self.finished.set()

    @property
    def running(self) -> bool:
        return not self.finished.is_set()

    def pause(self) -> None:
        self.clock.pause()

    def resume(self) -> None:
        self.clock.resume()

    def set_rate(self, rate: float) -> None:
        self.clock.set_rate(rate)

    def stop(self) -> Counter:
        """Stop playing now; the messages published per topic."""
        self._stop.set()
        self._thread.join(timeout=10)
        return self.published

    def wait(self, timeout: float | None = None) -> Counter:
        """Wait until the bag has played to its end (not with ``loop``); the messages per topic."""
        from course_helpers.core.waiting import wait_until

        if self.loop:
            raise CourseError("a looping playback never ends by itself; stop() it")
        limit = timeout if timeout is not None else self.info.duration_ns / 1e9 / self.clock.rate + 30.0
        wait_until(self.finished.is_set, limit, f"the playback of '{self.path.name}' to end")
        if self.error is not None:
            raise CourseError(f"playing '{self.path.name}' failed: {self.error}")
        return self.published

    def __repr__(self) -> str:
        return f"<Playback of {self.path.name!r}>"


def play(rt, path, **options) -> Playback:
    """Start playing the bag folder ``path`` (see :class:`Playback` for the options); returns at once."""
    playback = Playback(rt, path, **options)
    with _lock:
        _playbacks.append(playback)
    return playback


def playbacks(running_only: bool = False) -> list[Playback]:
    with _lock:
        found = list(_playbacks)
    return [p for p in found if p.running or not running_only]


def stop_all() -> list[Playback]:
    stopped = playbacks(running_only=True)
    for playback in stopped:
        playback.stop()
    return stopped
