"""Chapter package (see its modules)."""

from course_helpers.chapters.ch08_qos.qos import *  # noqa: F401,F403
