"""Chapter 10, the capstone: a warehouse robot built from ordinary rclpy nodes, and tools to study it.

* :mod:`.channels` - topic names and the QoS profile of each kind of channel;
* :mod:`.warehouse` - the simulated building: walls, shelves, docks, camera frames, LIDAR rays;
* :mod:`.robot` - the robot's nodes (camera, LIDAR, base, safety monitor, gripper, status light,
  perception) and the child-process target of its drivers;
* :mod:`.navigator` and :mod:`.missions` - the ``navigate`` action server and the mission runner;
* :mod:`.fleet` - starting a robot (drivers in a child process), several robots by namespace,
  the operator's e-stop button, the fleet manager's fleet-wide e-stop;
* :mod:`.states` - the state board that collects every node's latched state, and its graph;
* :mod:`.measure`, :mod:`.detectors`, :mod:`.plots` - the troubleshooting section;
* :mod:`.widgets` - a mission's progress bar, with a static record of the mission.

The notebook uses ``from course_helpers.chapters import ch10_capstone as capstone``; the names it
and the tests use are re-exported here, the rest is in the modules.
"""

from course_helpers.chapters.ch10_capstone.detectors import (
    detect_marker_numpy,
    detect_marker_python,
    time_detector,
)
from course_helpers.chapters.ch10_capstone.fleet import (
    EStopButton,
    FleetManager,
    Robot,
    start_robot,
    start_robots,
)
from course_helpers.chapters.ch10_capstone.measure import (
    Delivery,
    count_missed,
    endpoint_qos,
    measure_delivery,
    qos_table,
)
from course_helpers.chapters.ch10_capstone.missions import Mission, MissionRunner
from course_helpers.chapters.ch10_capstone.navigator import Navigator
from course_helpers.chapters.ch10_capstone.plots import plot_deliveries
from course_helpers.chapters.ch10_capstone.robot import (
    BaseController,
    CameraDriver,
    Gripper,
    LidarDriver,
    Perception,
    RobotNode,
    SafetyMonitor,
    StatusLight,
    make_robot_drivers,
)
from course_helpers.chapters.ch10_capstone.states import StateBoard, collect_states, state_graph, state_table
from course_helpers.chapters.ch10_capstone.warehouse import SHELVES, make_frame
from course_helpers.chapters.ch10_capstone.widgets import mission_html, mission_progress, mission_summary

__all__ = [
    "SHELVES", "BaseController", "CameraDriver", "Delivery", "EStopButton", "FleetManager", "Gripper",
    "LidarDriver", "Mission", "MissionRunner", "Navigator", "Perception", "Robot", "RobotNode",
    "SafetyMonitor", "StateBoard", "StatusLight", "collect_states", "count_missed", "detect_marker_numpy",
    "detect_marker_python", "endpoint_qos", "make_frame", "make_robot_drivers", "measure_delivery",
    "mission_html", "mission_progress", "mission_summary", "plot_deliveries", "qos_table", "start_robot",
    "start_robots", "state_graph", "state_table", "time_detector",
]
