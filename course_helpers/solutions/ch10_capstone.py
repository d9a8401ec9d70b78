"""Reference solution of chapter 10 (capstone), checked by ``course_helpers/checks/ch10_capstone.py``.

:data:`REFERENCE_DESIGN` lays out the warehouse robot: its nodes, and every topic,
service and action with its endpoints and QoS. The choices, channel by channel:

* camera and LIDAR: BEST_EFFORT, VOLATILE, small depth - a fresh sample replaces a
  lost one within milliseconds, and retransmitting a stale frame only adds delay;
* odometry and velocity commands: RELIABLE, VOLATILE - every command matters while it
  is fresh, but a node that starts later must not act on old ones;
* the e-stop: RELIABLE + TRANSIENT_LOCAL with depth 1 - every change arrives, and a
  node that starts after the button was pressed learns the current state at once;
* picking and placing are services (short, answer yes or no); driving is an action (long,
  with progress feedback, and it must be cancellable).
"""

from __future__ import annotations

SENSOR = {"reliability": "best_effort", "durability": "volatile", "depth": 5}
COMMAND = {"reliability": "reliable", "durability": "volatile", "depth": 10}
LATCHED = {"reliability": "reliable", "durability": "transient_local", "depth": 1}


def reference_design() -> dict:
    """The reference design of the warehouse robot (a new dict on every call)."""
    return {
        "namespace": "/robot1",
        "nodes": ["camera", "lidar", "base", "safety_monitor", "navigator", "gripper", "mission_runner"],
        "topics": [
            {"name": "camera/image_raw", "type": "sensor_msgs/msg/Image",
             "publishers": ["camera"], "subscribers": [], "qos": SENSOR},
            {"name": "scan", "type": "sensor_msgs/msg/LaserScan",
             "publishers": ["lidar"], "subscribers": ["safety_monitor"], "qos": SENSOR},
            {"name": "odom", "type": "nav_msgs/msg/Odometry",
             "publishers": ["base"], "subscribers": ["navigator", "gripper", "lidar"], "qos": COMMAND},
            {"name": "cmd_vel", "type": "geometry_msgs/msg/Twist",
             "publishers": ["navigator"], "subscribers": ["base"], "qos": COMMAND},
            {"name": "estop", "type": "course_interfaces/msg/EStop",
             "publishers": ["safety_monitor"],
             "subscribers": ["base", "navigator", "gripper", "mission_runner", "camera", "lidar"],
             "qos": LATCHED},
        ],
        "services": [
            {"name": "pick_item", "type": "course_interfaces/srv/PickItem",
             "server": "gripper", "clients": ["mission_runner"]},
            {"name": "place_item", "type": "std_srvs/srv/Trigger",
             "server": "gripper", "clients": ["mission_runner"]},
        ],
        "actions": [
            {"name": "navigate", "type": "course_interfaces/action/Navigate",
             "server": "navigator", "clients": ["mission_runner"]},
        ],
    }


REFERENCE_DESIGN = reference_design()
