"""Reference solution of chapter 09 (packages), checked by ``course_helpers/checks/packages.py``.

:func:`reference_package` returns the files of the ``robot_heartbeat`` package: the
heartbeat node of the notebook as a module with a ``main()``, and the package.xml,
setup.py, setup.cfg and marker file that make colcon build it as an ament_python
package with the console script ``heartbeat``.
"""

from __future__ import annotations

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

PACKAGE_XML = '''\
<?xml version="1.0"?>
<package format="3">
  <name>robot_heartbeat</name>
  <version>0.1.0</version>
  <description>Publishes a heartbeat so that a fleet manager knows the robot is alive</description>
  <maintainer email="student@example.com">Course Student</maintainer>
  <license>Apache-2.0</license>

  <exec_depend>rclpy</exec_depend>
  <exec_depend>std_msgs</exec_depend>

  <export>
    <build_type>ament_python</build_type>
  </export>
</package>
'''

SETUP_PY = '''\
from setuptools import setup

package_name = 'robot_heartbeat'

setup(
    name=package_name,
    version='0.1.0',
    packages=[package_name],
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    entry_points={
        'console_scripts': [
            'heartbeat = robot_heartbeat.heartbeat:main',
        ],
    },
)
'''

SETUP_CFG = '''\
[develop]
script_dir=$base/lib/robot_heartbeat
[install]
install_scripts=$base/lib/robot_heartbeat
'''


def reference_package() -> dict[str, str]:
    """The files of the robot_heartbeat package (relative path -> text)."""
    return {
        "package.xml": PACKAGE_XML,
        "setup.py": SETUP_PY,
        "setup.cfg": SETUP_CFG,
        "resource/robot_heartbeat": "",
        "robot_heartbeat/__init__.py": "",
        "robot_heartbeat/heartbeat.py": HEARTBEAT_MODULE,
    }
