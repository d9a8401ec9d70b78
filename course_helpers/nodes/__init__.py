"""Small, idiomatic nodes that several chapters reuse, in the kernel or in child processes.

Each is written the way a student would write it in a package: a Node subclass, a timer
instead of a sleep loop, units in comments.
"""

from course_helpers.nodes.chatter import Listener, Relay, Talker, make_relay, make_talker

__all__ = ["Listener", "Relay", "Talker", "make_relay", "make_talker"]
