"""Helpers shared by every notebook of the ROS 2 architecture course.

Start with ``from course_helpers import get_runtime``; each module's docstring
says which chapters use it.
"""

from .errors import CourseError, WaitTimeout
from .runtime import CourseRuntime, get_runtime, shutdown_runtime

__all__ = ["CourseError", "CourseRuntime", "WaitTimeout", "get_runtime", "shutdown_runtime"]
