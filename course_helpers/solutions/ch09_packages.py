"""Reference solution of chapter 09 (packages), checked by ``course_helpers/checks/ch09_packages.py``.

:func:`reference_package` returns the files of the ``robot_heartbeat`` package: the
heartbeat node of the notebook as a module with a ``main()``, and the package.xml,
setup.py, setup.cfg and marker file that make colcon build it as an ament_python
package with the console script ``heartbeat``.
"""

from __future__ import annotations

from course_helpers.chapters.ch09_packages import ament_python_files

HEARTBEAT_MODULE = '''\
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from std_msgs.msg import String


class Heartbeat(Node):
    """Says that the robot's software is alive, twice a second."""

    def __init__(self):
        super().__init__('heartbeat')
        self.publisher = self.create_publisher(String, 'heartbeat', 10)
        self.timer = self.create_timer(0.5, self.beat)  # period in seconds: 2 Hz

    def beat(self):
        self.publisher.publish(String(data='robot_heartbeat alive'))


def main(args=None):
    rclpy.init(args=args)
    node = Heartbeat()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass  # Ctrl+C or `kill`: leave quietly
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
'''

PACKAGE = "robot_heartbeat"
DESCRIPTION = "Publishes a heartbeat so that a fleet manager knows the robot is alive"


def reference_package() -> dict[str, str]:
    """The files of the robot_heartbeat package: relative path -> text.

    package.xml, setup.py, setup.cfg and the marker are what ``ros2 pkg create`` writes
    (:func:`course_helpers.chapters.ch09_packages.ament_python_files`), with rclpy and
    std_msgs as dependencies and ``heartbeat = robot_heartbeat.heartbeat:main`` as the
    console script; the node module is :data:`HEARTBEAT_MODULE`.
    """
    return ament_python_files(PACKAGE, "heartbeat", dependencies=["rclpy", "std_msgs"],
                              description=DESCRIPTION, node_source=HEARTBEAT_MODULE)
