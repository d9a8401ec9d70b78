"""The environment check of chapter 00: is everything the course needs installed and isolated?"""

from __future__ import annotations

import importlib
import sys

from course_helpers.checks import CheckReport
from course_helpers.core.domains import held_here

REQUIRED_MESSAGES = ["std_msgs.msg", "std_srvs.srv", "geometry_msgs.msg", "sensor_msgs.msg",
                     "test_msgs.action"]


def check_environment(rt=None) -> CheckReport:
    """Check Python, rclpy, the middleware, the message packages, the course interfaces and isolation."""
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport("Environment check")
    supported = (3, 10) <= sys.version_info[:2] <= (3, 13)
    version = f"{sys.version_info.major}.{sys.version_info.minor}"
    report.add("Python is a supported version (3.10-3.13)", supported,
               "" if supported else f"this is Python {version}",  # the same output on every supported one
               hint="Create the venv with a supported Python: make PYTHON=python3.12 lab")
    status = rt.status()
    report.add(f"rclpy {status['rclpy']} imports and its context is running", rt.context.ok(),
               hint="Restart the kernel (Kernel > Restart) and run the notebook from the top.")
    report.add(f"middleware is {status['rmw']}", status["rmw"] == "rmw_fastrtps_cpp",
               hint="Unset RMW_IMPLEMENTATION; the course uses Fast DDS (rmw_fastrtps_cpp).")
    missing = [m for m in REQUIRED_MESSAGES if not _importable(m)]
    report.add("message packages std_msgs, std_srvs, geometry_msgs, sensor_msgs, test_msgs",
               not missing, ", ".join(missing) and f"missing: {', '.join(missing)}",
               hint="Run `make lab` again; it installs everything in environment.txt.")
    report.add("the course's own interfaces (course_interfaces) are built",
               _importable("course_interfaces.srv"),
               hint="Run `make lab` again; it builds interfaces/course_interfaces.")
    domain = status["domain_id"]
    reserved = status["domain_chosen_by"] == "automatic" and held_here(domain)
    report.add("this kernel has its own ROS domain", reserved,
               "" if reserved else f"domain {domain} was set with ROS_DOMAIN_ID, not reserved",
               hint="Unset ROS_DOMAIN_ID and restart the kernel: the course then reserves a domain "
                    "no other kernel on this machine uses.")
    report.add("discovery stays on this machine (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)",
               status["discovery_range"] == "LOCALHOST",
               hint="You chose another range yourself; other machines on your network may see "
                    "your nodes.")
    return report


def _importable(module: str) -> bool:
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True
