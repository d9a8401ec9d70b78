"""Chapter package (see its modules)."""

from course_helpers.chapters.ch09_packages.workspace import *  # noqa: F401,F403
