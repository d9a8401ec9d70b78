"""Chapter 01's live ROS 1 beside ROS 2: a real master, rospy nodes, and what happens when a process dies.

* :mod:`.ros1` - ROS 1 from the system's packages: :func:`ros1_unavailable_reason`, :func:`start_master`
  (a :class:`Ros1Master` and its XML-RPC API), :func:`start_rospy`, :func:`rospy_source`;
* ``rospy_talker.py``, ``rospy_listener.py`` - the rospy nodes, run by the system Python;
* :mod:`.graph_watcher` - a ROS 2 node that reports which nodes it sees;
* :mod:`.failure` - the failure experiment on both systems (their steps: :func:`kill_the_master`,
  :func:`kill_the_first_node`); :func:`side_by_side` prints results
  (from :mod:`course_helpers.viz.failure_table`).

The notebooks use ``from course_helpers.chapters import ch01_ros1 as ros1``.
"""

# ruff: noqa: F401  (every import below is a re-export for the notebook)

from course_helpers.chapters.ch01_ros1.failure import (
    Ros2Side,
    kill_the_first_node,
    kill_the_master,
    ros1_failure_experiment,
    ros2_failure_experiment,
    start_failure_experiment,
    start_ros2_side,
    start_talking_pair,
)
from course_helpers.chapters.ch01_ros1.graph_watcher import GraphWatcher
from course_helpers.chapters.ch01_ros1.ros1 import (
    Ros1Master,
    install_hint,
    ros1_unavailable_reason,
    rospy_source,
    start_master,
    start_rospy,
    stop_ros1,
)
from course_helpers.viz.failure_table import FailureResult, side_by_side
