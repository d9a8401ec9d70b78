"""Recording: ``ros2 bag record`` in the kernel, in the background of the runtime's executor.

A :class:`Recording` has one node, ``rosbag2_recorder`` (the name ``ros2 bag record`` gives its
node), in the runtime's context and spun by an executor of its own, in a thread of its own: like
the recorder process of ``ros2 bag record``, it keeps taking messages while a callback of the
notebook's nodes blocks the runtime's executor (08b's slow subscriber sleeps in it). Like rosbag2's
recorder it

* looks for the topics to record in the graph every :data:`POLLING_INTERVAL_S` (rosbag2's
  ``--polling-interval`` default), so a topic that appears later is still recorded;
* subscribes to each with **raw** subscriptions (``create_subscription(..., raw=True)``): the
  callback gets the serialized CDR bytes, nothing is deserialized, so any message type works;
* stores the QoS every publisher offers (from the graph) in the bag, and subscribes with the QoS
  that connects to all of them (:func:`.qos.request_for_offers`);
* stamps each message with the time it was received (the middleware's receive time, system
  clock), or with the node's ROS time under ``use_sim_time`` (``--use-sim-time``).

The messages go to a :class:`.writer.BagWriter`, whose own thread writes them. The recording ends
after ``duration`` seconds or at :meth:`Recording.stop`, which closes the bag.
"""

from __future__ import annotations

import re
import threading
import time
from pathlib import Path

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter

from course_helpers.core.bags.qos import request_for_offers, to_bag_qos
from course_helpers.core.bags.writer import DEFAULT_STORAGE, BagWriter, WriteStats, check_new_bag
from course_helpers.core.errors import CourseError
from course_helpers.core.executors import SpinThread, plain_executor
from course_helpers.core.names import is_hidden
from course_helpers.core.validation import check_topic_name

NODE_NAME = "rosbag2_recorder"
POLLING_INTERVAL_S = 0.1  # rosbag2's --polling-interval default (100 ms)
_recordings: dict[str, Recording] = {}  # running and finished recordings of this kernel, by bag path
_lock = threading.Lock()


class Recording:
    """One bag being recorded. Make it with :func:`record`; ``stop()`` ends it, ``wait()`` waits for
    its ``duration`` to run out. ``stats`` says what was received, written and dropped."""

    def __init__(self, rt, path: Path, topics: list[str], all_topics: bool, regex: str | None,
                 storage: str, duration: float | None, use_sim_time: bool):
        self.rt = rt
        self.path = path
        self.wanted = topics
        self.all_topics = all_topics
        self.regex = re.compile(regex) if regex else None
        self.duration = duration
        self.use_sim_time = use_sim_time
        self.stats: WriteStats | None = None
        self.started = time.monotonic()
        self.finished = threading.Event()
        self.topics: dict[str, str] = {}  # topic -> type, once subscribed
        self._stopping = False
        self._close_lock = threading.Lock()
        self._writer = BagWriter(path, storage)
        self._subscriptions = []
        self.errors: list[BaseException] = []
        self.node = Node(NODE_NAME, context=rt.context, enable_rosout=False, start_parameter_services=False,
                         parameter_overrides=[Parameter("use_sim_time", value=use_sim_time)])
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._timer = self.node.create_timer(POLLING_INTERVAL_S, self._tick, clock=steady)
        self._subscribe_new()  # what the graph already shows, before the first message can come
        self._executor = plain_executor("single", rt.context)
        self._executor.add_node(self.node)
        self._spinner = SpinThread(self._executor, f"bag-record-{path.name}", self.errors.append).start()

    # ------------------------------------------------------------------ in the recorder's executor
    def _wanted(self, name: str) -> bool:
        if name in self.wanted:
            return True
        if is_hidden(name):
            return False
        return self.all_topics or bool(self.regex and self.regex.search(name))

    def _subscribe_new(self) -> None:
        if self._stopping:
            return
        for name, types in self.node.get_topic_names_and_types():
            if name in self.topics or not self._wanted(name) or len(types) != 1:
                continue
            publishers = self.node.get_publishers_info_by_topic(name)
            if not publishers:
                continue  # only subscribers so far: rosbag2 waits for a publisher to learn its QoS
            self._subscribe(name, types[0], [info.qos_profile for info in publishers],
                            type_hash_of(publishers))

    def _subscribe(self, name: str, type_name: str, offers: list, type_hash: str) -> None:
        from course_helpers.core.validation import resolve_interface

        self._writer.add_topic(name, type_name, [to_bag_qos(p) for p in offers], type_hash)
        writer, clock, sim = self._writer, self.node.get_clock(), self.use_sim_time

        def on_message(data: bytes, info: dict) -> None:
            stamp = clock.now().nanoseconds if sim else info["received_timestamp"]
            writer.write(name, stamp, data)

        self._subscriptions.append(self.node.create_subscription(
            resolve_interface(type_name, "msg"), name, on_message, request_for_offers(offers), raw=True))
        self.topics[name] = type_name

    def _tick(self) -> None:
        if self.duration is not None and time.monotonic() - self.started >= self.duration:
            self._end_subscriptions()
            threading.Thread(target=self._close, name=f"bag-close-{self.path.name}", daemon=True).start()
            return
        self._subscribe_new()

    def _end_subscriptions(self) -> None:
        if self._stopping:
            return
        self._stopping = True
        self._timer.cancel()
        for subscription in self._subscriptions:
            self.node.destroy_subscription(subscription)
        self._subscriptions.clear()

    # ------------------------------------------------------------------ in any thread
    def _close(self) -> None:
        with self._close_lock:
            if self.stats is not None:
                return
            try:
                self._spinner.stop()
                self._end_subscriptions()  # (no-op if the duration already ended them)
                self.stats = self._writer.close()
            finally:
                self._executor.shutdown(timeout_sec=1.0)
                self.node.destroy_node()
                self.finished.set()

    @property
    def running(self) -> bool:
        return not self.finished.is_set()

    def stop(self) -> WriteStats:
        """End the recording now (if it still runs) and close the bag; what it wrote."""
        if not self.finished.is_set():
            self._close()
        return self.stats

    def wait(self, timeout: float | None = None) -> WriteStats:
        """Wait until the recording has ended by its ``duration`` and the bag is closed."""
        from course_helpers.core.waiting import wait_until

        if self.duration is None and timeout is None:
            raise CourseError(f"the recording to '{self.path}' has no duration: it runs until stop()")
        limit = timeout if timeout is not None else self.duration + 30.0
        wait_until(self.finished.is_set, limit, f"the recording to '{self.path}' to end")
        return self.stats

    def __repr__(self) -> str:
        return f"<Recording of {self.path.name!r}>"


def type_hash_of(publishers) -> str:
    """The RIHS01 type hash the publishers announce, as rosbag2 writes it ('' if they disagree)."""
    hashes = {f"RIHS{p.topic_type_hash.version:02d}_{bytes(p.topic_type_hash.value).hex()}"
              for p in publishers if p.topic_type_hash.version == 1}
    return hashes.pop() if len(hashes) == 1 else ""


def record(rt, output: str | Path, topics=(), all_topics: bool = False, regex: str | None = None,
           storage: str = DEFAULT_STORAGE, duration: float | None = None, overwrite: bool = False,
           use_sim_time: bool = False) -> Recording:
    """Start recording ``topics`` (or every topic with ``all_topics``, or those matching ``regex``)
    into the bag folder ``output``; returns the running :class:`Recording` at once.

    Refuses an existing ``output`` unless ``overwrite`` (then only a former bag is replaced), a
    topic name that is not valid, and a duration that is not > 0.
    """
    topics = [check_topic_name(t if t.startswith("/") else "/" + t) for t in topics]
    if not (topics or all_topics or regex):
        raise CourseError("Need to specify at least one option out of --all, --regex or a list of topics")
    if duration is not None and not duration > 0:
        raise CourseError(f"duration must be > 0 seconds, got {duration!r}")
    if regex:
        try:
            re.compile(regex)
        except re.error as exc:
            raise CourseError(f"invalid --regex {regex!r}: {exc}") from None
    path = Path(output).expanduser().absolute()
    with _lock:
        running = _recordings.get(str(path))
        if running is not None and running.running:
            raise CourseError(f"'{path.name}' is being recorded right now; stop it first (%ros2 bag stop)")
    check_new_bag(path, overwrite)
    rt.start()
    recording = Recording(rt, path, topics, all_topics, regex, storage, duration, use_sim_time)
    with _lock:
        _recordings[str(path)] = recording
    return recording


def recordings(running_only: bool = False) -> list[Recording]:
    """This kernel's recordings, oldest first (only those still running with ``running_only``)."""
    with _lock:
        found = list(_recordings.values())
    return [r for r in found if r.running or not running_only]


def stop_all() -> list[Recording]:
    """Stop every running recording (the runtime's stop calls this); the ones stopped."""
    stopped = recordings(running_only=True)
    for recording in stopped:
        recording.stop()
    return stopped
