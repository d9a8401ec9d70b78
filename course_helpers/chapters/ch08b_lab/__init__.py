"""Chapter package (see its modules)."""

from course_helpers.chapters.ch08b_lab.engine import *  # noqa: F401,F403
