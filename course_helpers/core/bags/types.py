"""What a bag stores about a message type: its definition and its type hash (RIHS01).

A rosbag2 writer puts each type's full definition (the ``.msg`` text with every type it uses) in
the file, so that a reader needs no ROS install to decode it: MCAP keeps it as the channel's
schema (encoding ``ros2msg``). The course finds the ``.msg`` files where the venv's interface
packages installed them (``<prefix>/share/<package>/msg/<Name>.msg``, for each prefix on
``AMENT_PREFIX_PATH`` and the venv's own), and lets ``rosbags`` assemble the definition and the hash,
so any message type the venv knows can be recorded.
"""

from __future__ import annotations

import functools
import os
import sys
from pathlib import Path

from rosbags.typesys import get_types_from_msg, get_typestore
from rosbags.typesys.stores import Stores

from course_helpers.core.errors import CourseError


def _prefixes() -> list[Path]:
    listed = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    return [Path(p) for p in dict.fromkeys([*listed, sys.prefix])]


def _msg_file(type_name: str) -> Path:
    package, kind, name = type_name.split("/")
    for prefix in _prefixes():
        path = prefix / "share" / package / kind / f"{name}.msg"
        if path.is_file():
            return path
    raise CourseError(f"unknown message type {type_name!r}: no {package}/{kind}/{name}.msg under "
                      f"{', '.join(str(p / 'share') for p in _prefixes())}; is its interface package "
                      f"installed in this venv?")


def _referenced(fields) -> set[str]:
    """The message types that ``fields`` (rosbags' parsed form of a definition) name."""
    names = set()
    for _name, (nodetype, detail) in fields:
        while isinstance(detail, tuple) and len(detail) == 2 and isinstance(detail[0], tuple):
            (nodetype, detail), _size = detail  # an array or sequence: look at its element type
        if isinstance(detail, str):
            names.add(detail)
    return names


@functools.cache
def definition(type_name: str) -> tuple[str, str]:
    """``(message definition, RIHS01 hash)`` of a type such as 'std_msgs/msg/String'.

    Raises CourseError naming the type when its ``.msg`` file cannot be found.
    """
    if type_name.count("/") != 2 or type_name.split("/")[1] != "msg":
        raise CourseError(f"{type_name!r} is not a message type name; use package/msg/Name, "
                          f"e.g. std_msgs/msg/String")
    store = get_typestore(Stores.EMPTY)
    todo, seen = [type_name], set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        parsed = get_types_from_msg(_msg_file(name).read_text(encoding="utf-8"), name)
        store.register(parsed)
        for _consts, fields in parsed.values():
            todo.extend(_referenced(fields) - seen)
    text, _format = store.generate_msgdef(type_name, ros_version=2)
    return text, store.hash_rihs01(type_name)
