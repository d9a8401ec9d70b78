"""rosbag2 in the kernel: record, inspect and play bags that ROS 2's own tools read.

A bag is a folder with ``metadata.yaml`` and one storage file, MCAP (rosbag2's default since
Iron) or SQLite 3, written and read with ``rosbags`` (pure Python; no ROS install needed). The
engine is split by job:

* :mod:`.qos` - the QoS profiles a bag keeps, and rosbag2's rules for recording and playback;
* :mod:`.types` - each type's message definition and hash, from the venv's ``.msg`` files;
* :mod:`.writer` - writing a bag in a thread of its own, ``metadata.yaml`` as Jazzy writes it;
* :mod:`.recorder` - ``record()``: raw subscriptions in the runtime's executor;
* :mod:`.reader` - ``bag_info()``, ``format_info()`` (``ros2 bag info``), ``messages()``, ``read()``;
* :mod:`.player` - ``play()``: the serialized messages at their recorded pace, ``/clock`` optional;
* :mod:`.replay` - ``SimReplay``: a bag replayed exactly under a SimClock (checkers, debugging).

The ``%ros2 bag`` magic (``course_helpers.notebook.ros2cli.bag``) is built on these.
"""

from course_helpers.core.bags.player import Playback, play, playbacks
from course_helpers.core.bags.reader import BagInfo, TopicInfo, bag_info, format_info, messages, read
from course_helpers.core.bags.recorder import Recording, record, recordings
from course_helpers.core.bags.replay import SimReplay
from course_helpers.core.bags.writer import DEFAULT_STORAGE, STORAGES, BagWriter

__all__ = ["DEFAULT_STORAGE", "STORAGES", "BagInfo", "BagWriter", "Playback", "Recording", "SimReplay",
           "TopicInfo", "bag_info", "format_info", "messages", "play", "playbacks", "read", "record",
           "recordings"]
