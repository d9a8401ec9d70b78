"""Reference solution of chapter 07's exercise (a robot its team hears and the class cannot see)."""

from __future__ import annotations

from rclpy.context import Context
from rclpy.node import Node
from std_msgs.msg import String


def private_context(domain_id):
    """A new rclpy context whose participant joins ROS domain ``domain_id``."""
    context = Context()
    context.init(domain_id=domain_id)  # installs no signal handler and leaves os.environ alone
    return context


class PrivateRobot(Node):
    """The team's robot: publishes its status five times a second, in the context it is given."""

    def __init__(self, context=None):
        super().__init__('private_robot', context=context)
        self.publisher = self.create_publisher(String, 'robot_status', 10)
        self.timer = self.create_timer(0.2, self.tick)  # period in seconds: 5 Hz

    def tick(self):
        self.publisher.publish(String(data='ok'))
