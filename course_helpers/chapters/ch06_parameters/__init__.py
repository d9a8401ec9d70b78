"""Chapter 06, parameters: files, live retuning and a launch equivalent.

* :mod:`.files` - what a ``--params-file`` YAML file gives one node, and the arguments that load it;
* :mod:`.nodes` - the configurable talker and listener that the chapter starts;
* :mod:`.rate_tuner` - retune a running node's rate through its parameter services and measure it;
* :mod:`.launching` - start configured nodes in child processes together, stop them together, and
  write the equivalent launch file for a ROS 2 installation.

The notebook uses ``from course_helpers.chapters.ch06_parameters import <name>``.
"""

# ruff: noqa: F401  (every import below is a re-export for the notebook)
from course_helpers.chapters.ch06_parameters.files import load_parameter_file, params_file_arguments
from course_helpers.chapters.ch06_parameters.launching import LaunchGroup, NodeLaunch, launch, launch_file
from course_helpers.chapters.ch06_parameters.nodes import (
    NODE_KINDS,
    CountingListener,
    RateTalker,
    make_configured_node,
)
from course_helpers.chapters.ch06_parameters.rate_tuner import RateTuner
