"""The warehouse robot's channels: the topic names and the QoS profile each kind of channel uses.

* sensor streams (camera, LIDAR): BEST_EFFORT, VOLATILE, depth 5 - a late frame is
  worthless and a lost one is replaced 33 ms later;
* velocity commands and odometry: RELIABLE, VOLATILE, depth 10 - every message matters
  while it is fresh, old ones are stale;
* states a node joining later must still learn (the e-stop, node states, the mission
  status): RELIABLE, TRANSIENT_LOCAL, depth 1.

Names without a leading slash are relative: each robot's nodes resolve them under the robot's
namespace (``scan`` is ``/robot1/scan`` on robot 1). The fleet's e-stop is absolute: one topic
that every robot of the fleet reads.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

SENSOR_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5,
                        reliability=ReliabilityPolicy.BEST_EFFORT,
                        durability=DurabilityPolicy.VOLATILE)
COMMAND_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
ODOM_QOS = COMMAND_QOS
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
ESTOP_QOS = LATCHED_QOS

CAMERA_TOPIC = "camera/image_raw"
DETECTIONS_TOPIC = "perception/detections"
PROCESSING_TIME_TOPIC = "~/processing_time_ms"  # std_msgs/Float64: how long each frame took [ms]
FLEET_ESTOP_TOPIC = "/fleet/estop"  # absolute: the fleet manager's e-stop for every robot
STATE_TOPIC = "~/_state"  # hidden (leading underscore): infrastructure for the state board
