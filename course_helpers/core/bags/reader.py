"""Reading a bag: what ``ros2 bag info`` prints, and its messages in time order.

:func:`open_bag` reads a rosbag2 folder (``metadata.yaml`` and its MCAP or SQLite files), written by
the course or by rosbag2 itself, with ``rosbags``: no ROS install is needed to read it. Every
problem with the folder (missing, not a bag, unreadable) is a :class:`CourseError` naming it.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from rosbags.interfaces import Qos
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.errors import ReaderError

from course_helpers.core.bags.qos import describe
from course_helpers.core.errors import CourseError

INDENT = 19  # rosbag2's format_bag_metadata: the width of its longest label, 'Topic information: '


@dataclass
class TopicInfo:
    """One topic of a bag: name, type, message count, serialization format and the offered QoS."""

    name: str
    type: str
    count: int
    serialization_format: str
    offered: list[Qos] = field(default_factory=list)


@dataclass
class BagInfo:
    """What ``metadata.yaml`` says about a bag (the numbers ``ros2 bag info`` prints)."""

    path: Path
    storage: str
    files: list[str]
    size_bytes: int
    ros_distro: str
    start_ns: int
    duration_ns: int
    message_count: int
    topics: list[TopicInfo]
    version: int

    @property
    def end_ns(self) -> int:
        return self.start_ns + self.duration_ns

    def topic(self, name: str) -> TopicInfo:
        """The topic called ``name``; CourseError naming the bag's topics if it has none."""
        for topic in self.topics:
            if topic.name == name:
                return topic
        raise CourseError(f"topic {name!r} is not in the bag '{self.path.name}'; it holds "
                          f"{', '.join(t.name for t in self.topics) or 'no topic'}")


def resolve(path: str | os.PathLike) -> Path:
    """The bag folder ``path`` (relative to the working directory: a notebook's own folder)."""
    return Path(path).expanduser().absolute()


def check_bag(path: str | os.PathLike) -> Path:
    """``path`` as an existing bag folder, or CourseError saying what it is instead."""
    folder = resolve(path)
    if not folder.exists():
        raise CourseError(f"no bag '{path}': {folder} does not exist (record one with "
                          f"%ros2 bag record -o {Path(path).name} TOPIC...)")
    if not (folder / "metadata.yaml").is_file():
        if folder.is_dir() and any(p.suffix in (".mcap", ".db3") for p in folder.iterdir()):
            raise CourseError(f"'{path}' has no metadata.yaml yet: a recording writes it when it ends "
                              f"(%ros2 bag stop {Path(path).name} ends it now)")
        raise CourseError(f"'{path}' is not a bag: a bag is a folder with a metadata.yaml, and "
                          f"{folder} has none")
    return folder


def bag_info(path: str | os.PathLike) -> BagInfo:
    """The :class:`BagInfo` of the bag folder ``path``."""
    folder = check_bag(path)
    try:
        meta = yaml.safe_load((folder / "metadata.yaml").read_text(encoding="utf-8"))
        meta = meta["rosbag2_bagfile_information"]
        with _opened(folder) as reader:
            offered = {c.topic: list(c.ext.offered_qos_profiles) for c in reader.connections}
        topics = [TopicInfo(t["topic_metadata"]["name"], t["topic_metadata"]["type"], t["message_count"],
                            t["topic_metadata"]["serialization_format"],
                            offered.get(t["topic_metadata"]["name"], []))
                  for t in meta["topics_with_message_count"]]
        files = list(meta["relative_file_paths"])
        return BagInfo(folder, meta["storage_identifier"], files,
                       sum((folder / f).stat().st_size for f in files if (folder / f).exists()),
                       meta.get("ros_distro") or "unknown",
                       int(meta["starting_time"]["nanoseconds_since_epoch"]),
                       int(meta["duration"]["nanoseconds"]), int(meta["message_count"]), topics,
                       int(meta["version"]))
    except CourseError:
        raise
    except (yaml.YAMLError, KeyError, TypeError, ValueError, OSError) as exc:
        raise CourseError(f"cannot read the bag '{path}': its metadata.yaml is damaged ({exc!r})") from None


@contextlib.contextmanager
def _opened(folder: Path) -> Iterator[Reader]:
    """A rosbags Reader on ``folder``, its errors turned into CourseError."""
    try:
        reader = Reader(folder)
        reader.open()
    except (ReaderError, FileNotFoundError, OSError, ValueError, KeyError, IndexError) as exc:
        raise CourseError(f"cannot read the bag '{folder.name}': {exc}") from None
    try:
        yield reader
    finally:
        with contextlib.suppress(Exception):
            reader.close()


def messages(path: str | os.PathLike, topics: list[str] | None = None) -> Iterator[tuple[str, int, bytes]]:
    """``(topic, timestamp_ns, serialized bytes)`` of the bag's messages in time order, of ``topics``
    only if given (CourseError for a topic the bag does not hold)."""
    folder = check_bag(path)
    info = bag_info(folder)
    for name in topics or []:
        info.topic(name)
    with _opened(folder) as reader:
        chosen = [c for c in reader.connections if not topics or c.topic in topics]
        try:
            for connection, stamp, data in reader.messages(connections=chosen):
                yield connection.topic, stamp, bytes(data)
        except (ReaderError, ValueError, KeyError, IndexError, OSError) as exc:
            raise CourseError(f"the bag '{folder.name}' is damaged: {exc}") from None


def read(path: str | os.PathLike, topic: str) -> list[tuple[int, object]]:
    """``(timestamp_ns, message)`` for every message of ``topic``, deserialized with the venv's type."""
    from rclpy.serialization import deserialize_message

    msg_class = message_class_of(bag_info(path).topic(topic))
    return [(stamp, deserialize_message(data, msg_class)) for _t, stamp, data in messages(path, [topic])]


def message_class_of(topic: TopicInfo):
    """The venv's class for a bag topic's type; CourseError if this venv does not know the type."""
    from course_helpers.core.validation import resolve_interface

    try:
        return resolve_interface(topic.type, "msg")
    except CourseError:
        raise CourseError(f"topic {topic.name} has type {topic.type}, which this venv does not know "
                          f"(its interface package is not installed); leave it out with --topics") from None


# ---------------------------------------------------------------------- ros2 bag info
def _size(n: int) -> str:
    """rosbag2's format_file_size: 1024-based, one decimal above bytes."""
    size, units = float(n), ["B", "KiB", "MiB", "GiB", "TiB"]
    index = 0
    while size >= 1024 and index < 4:
        size /= 1024
        index += 1
    return f"{size:.0f} {units[index]}" if index == 0 else f"{size:.1f} {units[index]}"


def _seconds(ns: int) -> str:
    return f"{ns // 10**9}.{ns % 10**9:09d}"


def _time_point(ns: int) -> str:
    local = time.localtime(ns // 10**9)
    return (f"{time.strftime('%b %e %Y', local)} {time.strftime('%H:%M:%S', local)}.{ns % 10**9:09d} "
            f"({_seconds(ns)})")


def format_info(info: BagInfo, qos: bool = False) -> str:
    """The text ``ros2 bag info`` (Jazzy) prints for the bag; with ``qos`` each topic's recorded
    offers follow it (a course addition: rosbag2 keeps them in metadata.yaml)."""
    pad = " " * INDENT
    lines = ["", "Files:             " + f"\n{pad}".join(info.files),
             f"Bag size:          {_size(info.size_bytes)}",
             f"Storage id:        {info.storage}",
             f"ROS Distro:        {info.ros_distro}",
             f"Duration:          {_seconds(info.duration_ns)}s",
             f"Start:             {_time_point(info.start_ns) if info.message_count else '-'}",
             f"End:               {_time_point(info.end_ns) if info.message_count else '-'}",
             f"Messages:          {info.message_count}"]
    rows = []
    for topic in info.topics:
        rows.append(f"Topic: {topic.name} | Type: {topic.type} | Count: {topic.count} | "
                    f"Serialization Format: {topic.serialization_format}")
        if qos:
            offers = [f"  QoS offered: {describe(q)}" for q in topic.offered]
            rows += offers or ["  QoS offered: (none recorded)"]
    lines.append("Topic information: " + f"\n{pad}".join(rows))
    lines += ["Service:           0", "Service information: "]
    return "\n".join(lines)
