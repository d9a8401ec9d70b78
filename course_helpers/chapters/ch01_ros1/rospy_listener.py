"""A ROS 1 listener, run by the system Python that ROS 1 belongs to (never imported by the kernel).

``python3 rospy_listener.py NAME TOPIC`` with ``ROS_MASTER_URI`` set. It reports ``ready`` once
its subscriber exists, and ``heard`` for every message, over the course's process channel.
"""

import sys

import rospy
from std_msgs.msg import String

from course_helpers.core.channel import report
from course_helpers.core.child import die_with_parent


class Listener:
    """Subscribes to ``topic``; the master tells it where the publishers are."""

    def __init__(self, topic: str):
        self.subscriber = rospy.Subscriber(topic, String, self.on_message)

    def on_message(self, msg: String) -> None:
        report("heard", data=msg.data)


def main(argv: list[str]) -> None:
    die_with_parent()
    name, topic = argv[1], argv[2]
    rospy.init_node(name)
    Listener(topic)
    report("ready", node=rospy.get_name(), uri=rospy.get_node_uri())
    rospy.spin()


if __name__ == "__main__":
    main(sys.argv)
