"""Writing a bag: a rosbag2 folder (``metadata.yaml`` and one storage file) written by ``rosbags``.

:class:`BagWriter` takes serialized messages from any thread (a subscription callback) and writes
them in a thread of its own, so a slow disk never stalls the executor. Like rosbag2's message
cache, the messages waiting for the disk are bounded (:data:`CACHE_LIMIT_BYTES`, rosbag2's
``--max-cache-size`` default): a message that does not fit any more is dropped and counted, never
waited for. At :meth:`BagWriter.close` it writes ``metadata.yaml`` the way Jazzy's rosbag2 does
(version 9, QoS profiles as a list with policies by name, ``ros_distro``), so that ``ros2 bag info``
on a ROS machine reads the folder.
"""

from __future__ import annotations

import collections
import os
import shutil
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from rosbags.interfaces import Qos
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.errors import WriterError

from course_helpers.core.bags import types
from course_helpers.core.errors import CourseError

STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
DEFAULT_STORAGE = "mcap"  # rosbag2's default since Iron
CACHE_LIMIT_BYTES = 100 * 1024 * 1024  # rosbag2's default --max-cache-size (100 MiB)
ROS_DISTRO = "jazzy"  # the distribution of the venv's rclpy: what rosbag2 stores from ROS_DISTRO
METADATA = "metadata.yaml"


def check_new_bag(path: Path, overwrite: bool) -> None:
    """Refuse to write over an existing folder, as ``ros2 bag record`` does; with ``overwrite`` a
    former *bag* (a folder with ``metadata.yaml``, or an empty one) is removed first, nothing else."""
    if not path.exists():
        return
    if not overwrite:
        raise CourseError(f"Output folder '{path}' already exists (ros2 bag record never writes over a "
                          f"bag); choose another name, or add --overwrite to replace it")
    if not path.is_dir() or not ((path / METADATA).is_file() or not any(path.iterdir())):
        raise CourseError(f"'{path}' exists and is not a bag (no {METADATA} in it); --overwrite replaces "
                          f"only a bag folder, so move it away yourself")
    shutil.rmtree(path)


@dataclass
class _Topic:
    name: str
    type: str
    offered: list[Qos]
    connection: object = None
    count: int = 0


@dataclass
class WriteStats:
    """What a writer did: messages and bytes received, written, and dropped because the cache was full."""

    received: int = 0
    written: int = 0
    dropped: int = 0
    bytes_written: int = 0
    write_seconds: float = 0.0  # the writer thread's time inside the storage's write calls
    per_topic: dict = field(default_factory=dict)


class BagWriter:
    """``BagWriter(path, storage)``; ``add_topic(name, type, offered)``; ``write(topic, ns, data)``
    from any thread; ``close()`` once. ``path`` must not exist (see :func:`check_new_bag`).

    One thread of its own opens the storage, adds the topics, writes and closes (SQLite allows its
    connection in one thread only); the others only queue work for it.
    """

    def __init__(self, path: str | os.PathLike, storage: str = DEFAULT_STORAGE,
                 cache_limit_bytes: int = CACHE_LIMIT_BYTES):
        if storage not in STORAGES:
            raise CourseError(f"storage {storage!r} is not one of {', '.join(STORAGES)}")
        self.path = Path(path)
        self.storage = storage
        self.stats = WriteStats()
        self._topics: dict[str, _Topic] = {}
        self._queue: collections.deque = collections.deque()  # ('topic', _Topic) or (_Topic, ns, bytes)
        self._queued_bytes = 0
        self._limit = cache_limit_bytes
        self._lock = threading.Condition()
        self._closing = False
        self._error: BaseException | None = None
        self._opened = threading.Event()
        self._thread = threading.Thread(target=self._work, name=f"bag-writer-{self.path.name}", daemon=True)
        self._thread.start()
        self._opened.wait()
        if self._error is not None:
            self._thread.join()
            raise CourseError(f"cannot write the bag '{self.path}': {self._error}")

    def add_topic(self, name: str, type_name: str, offered: list[Qos], type_hash: str = "") -> None:
        """Declare a topic before its first message (its definition is looked up now). ``type_hash``:
        the RIHS01 hash the publishers announced (rosbag2 stores theirs), else the definition's."""
        text, rihs01 = types.definition(type_name)
        rihs01 = type_hash or rihs01
        with self._lock:
            if name in self._topics:
                return
            topic = _Topic(name, type_name, list(offered))
            topic.connection = (text, rihs01)  # the writer thread replaces it with the bag's connection
            self._topics[name] = topic
            self._queue.append(("topic", topic))
            self._lock.notify()

    def write(self, topic: str, timestamp_ns: int, data: bytes) -> bool:
        """Queue one serialized message; False if it was dropped (the cache is full or closed)."""
        with self._lock:
            self.stats.received += 1
            if self._closing or self._queued_bytes + len(data) > self._limit:
                self.stats.dropped += 1
                return False
            self._queue.append((self._topics[topic], timestamp_ns, data))
            self._queued_bytes += len(data)
            self._lock.notify()
        return True

    def _work(self) -> None:
        try:
            writer = Writer(self.path, version=Writer.VERSION_LATEST, storage_plugin=STORAGES[self.storage])
            writer.open()
        except (WriterError, OSError) as exc:
            self._error = exc
            self._opened.set()
            return
        self._opened.set()
        while True:
            with self._lock:
                while not self._queue and not self._closing:
                    self._lock.wait()
                if not self._queue:
                    break
                item = self._queue.popleft()
                if item[0] != "topic":
                    self._queued_bytes -= len(item[2])
            if self._error is not None:
                continue
            try:
                self._handle(writer, item)
            except Exception as exc:  # a full disk: keep the first error, report it at close
                self._error = exc
        try:
            writer.close()
        except Exception as exc:
            self._error = self._error or exc

    def _handle(self, writer: Writer, item: tuple) -> None:
        if item[0] == "topic":
            topic = item[1]
            text, rihs01 = topic.connection
            topic.connection = writer.add_connection(topic.name, topic.type, msgdef=text, rihs01=rihs01,
                                                     offered_qos_profiles=topic.offered)
            return
        topic, stamp, data = item
        started = time.perf_counter()
        writer.write(topic.connection, stamp, data)
        self.stats.write_seconds += time.perf_counter() - started
        topic.count += 1
        self.stats.written += 1
        self.stats.bytes_written += len(data)

    def close(self) -> WriteStats:
        """Write what is queued, close the storage file and write ``metadata.yaml``; the stats."""
        with self._lock:
            if self._closing:
                return self.stats
            self._closing = True
            self._lock.notify()
        self._thread.join()
        self.stats.per_topic = {name: topic.count for name, topic in self._topics.items()}
        if (self.path / METADATA).is_file():
            _jazzy_metadata(self.path)
        if self._error is not None:
            raise CourseError(f"writing the bag '{self.path}' failed: {self._error}")
        return self.stats


def _jazzy_metadata(path: Path) -> None:
    """Rewrite ``metadata.yaml`` with Jazzy's keys, in Jazzy's order (``rosbag2_storage/yaml.hpp``)."""
    meta_path = path / METADATA
    info = yaml.safe_load(meta_path.read_text(encoding="utf-8"))["rosbag2_bagfile_information"]
    order = ("version", "storage_identifier", "duration", "starting_time", "message_count",
             "topics_with_message_count", "compression_format", "compression_mode", "relative_file_paths",
             "files", "custom_data", "ros_distro")
    info["ros_distro"] = os.environ.get("ROS_DISTRO") or ROS_DISTRO
    info["topics_with_message_count"] = [
        {"topic_metadata": {**{key: entry["topic_metadata"][key] for key in
                               ("name", "type", "serialization_format")},
                            "offered_qos_profiles": [_ordered_qos(q) for q in
                                                     entry["topic_metadata"]["offered_qos_profiles"]],
                            "type_description_hash": entry["topic_metadata"]["type_description_hash"]},
         "message_count": entry["message_count"]}
        for entry in info["topics_with_message_count"]]
    info["files"] = [{key: entry[key] for key in ("path", "starting_time", "duration", "message_count")}
                     for entry in info["files"]]
    ordered = {"rosbag2_bagfile_information": {key: info[key] for key in order}}
    meta_path.write_text(yaml.safe_dump(ordered, sort_keys=False, default_flow_style=False), encoding="utf-8")


def _ordered_qos(qos: dict) -> dict:
    """One offered profile with its keys in the order rosbag2's ``convert<rclcpp::QoS>::encode`` emits."""
    times = ("deadline", "lifespan", "liveliness_lease_duration")
    return {key: ({"sec": qos[key]["sec"], "nsec": qos[key]["nsec"]} if key in times else qos[key])
            for key in ("history", "depth", "reliability", "durability", "deadline", "lifespan", "liveliness",
                        "liveliness_lease_duration", "avoid_ros_namespace_conventions")}
