"""The warehouse robot's channels: the topic names and the QoS profile each kind of channel uses.

* sensor streams (camera, LIDAR): BEST_EFFORT, VOLATILE, depth 5 - a late frame is
  worthless and a lost one is replaced 33 ms later;
* velocity commands and odometry: RELIABLE, VOLATILE, depth 10 - every message matters
  while it is fresh, old ones are stale;
* states a node joining later must still learn (the e-stop, node states, the mission
  status): RELIABLE, TRANSIENT_LOCAL, depth 1.
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
STATE_TOPIC = "~/_state"  # hidden (leading underscore): infrastructure for the state board
