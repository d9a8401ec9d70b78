"""Chapter package (see its modules)."""

from course_helpers.chapters.ch10_capstone.capstone import *  # noqa: F401,F403
