"""Chapter package (see its modules)."""

from course_helpers.chapters.ch07_dds.dds import *  # noqa: F401,F403
