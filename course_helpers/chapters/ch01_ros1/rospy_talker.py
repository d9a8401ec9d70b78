"""A ROS 1 talker, run by the system Python that ROS 1 belongs to (never imported by the kernel).

``python3 rospy_talker.py NAME TOPIC RATE_HZ`` with ``ROS_MASTER_URI`` set. rospy has no node
class: the process is the node, ``rospy.init_node`` registers it with the master, and a publisher
sends on a timer. It reports ``ready`` (its name and XML-RPC URI) over the course's process channel.
"""

import sys

import rospy
from std_msgs.msg import String

from course_helpers.core.channel import report
from course_helpers.core.child import die_with_parent


class Talker:
    """Publishes 'hello N' on ``topic`` every 1/``rate_hz`` seconds."""

    def __init__(self, topic: str, rate_hz: float):
        self.count = 0
        self.publisher = rospy.Publisher(topic, String, queue_size=10)
        self.timer = rospy.Timer(rospy.Duration(1.0 / rate_hz), self.tick)  # period in seconds

    def tick(self, _event) -> None:
        self.publisher.publish(String(data=f"hello {self.count}"))
        self.count += 1


def main(argv: list[str]) -> None:
    die_with_parent()
    name, topic, rate_hz = argv[1], argv[2], float(argv[3])
    rospy.init_node(name)  # registers with the master named by ROS_MASTER_URI
    Talker(topic, rate_hz)
    report("ready", node=rospy.get_name(), uri=rospy.get_node_uri())
    rospy.spin()  # until SIGTERM or SIGINT


if __name__ == "__main__":
    main(sys.argv)
