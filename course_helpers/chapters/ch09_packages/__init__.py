"""Packages and interfaces (notebook ``09_packages_and_interfaces``): real colcon and rosidl builds.

* ``workspace``: :class:`Workspace`, a colcon workspace in a temporary directory;
* ``package_files``: the files of an ament_python or interface package as text, and a package's
  folder read into them (``read_package``) or written from them;
* ``colcon``: ``colcon build`` and :class:`ColconBuild`;
* ``environment``: what ``source install/setup.bash`` does, from colcon's ``.dsv`` hooks;
* ``executables``: find and run a package's executables as ``ros2 run`` does;
* ``provisioned``: a package run where only the ROS packages its package.xml declares are installed;
* ``interfaces``: create, build and load new interface packages; :class:`MessagePublisher`;
* ``progress``: :func:`build_progress`, a live indicator for builds that leaves a record of the steps.
"""

from __future__ import annotations

from course_helpers.chapters.ch09_packages.colcon import ColconBuild
from course_helpers.chapters.ch09_packages.executables import (
    find_executable,
    running_processes,
    start_process,
    stop_process,
    wait_for_process_node,
)
from course_helpers.chapters.ch09_packages.interfaces import (
    MessagePublisher,
    build_interface_package,
    create_interface_package,
    interface_env,
    kernel_prefix,
    load_interfaces,
)
from course_helpers.chapters.ch09_packages.package_files import (
    ament_python_files,
    package_xml,
    read_manifest,
    read_package,
    setup_cfg,
    setup_py,
    write_package_files,
)
from course_helpers.chapters.ch09_packages.progress import build_progress
from course_helpers.chapters.ch09_packages.workspace import Workspace

__all__ = ["ColconBuild", "MessagePublisher", "Workspace", "ament_python_files", "build_interface_package",
           "build_progress", "create_interface_package", "find_executable", "interface_env", "kernel_prefix",
           "load_interfaces", "package_xml", "read_manifest", "read_package", "running_processes",
           "setup_cfg", "setup_py", "start_process", "stop_process", "wait_for_process_node",
           "write_package_files"]
