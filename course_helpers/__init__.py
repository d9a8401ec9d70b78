"""Helpers shared by every notebook of the ROS 2 architecture course.

Start a notebook with ``from course_helpers import get_runtime`` and ``rt = get_runtime()``.
The folders are the layers, and a module imports only from the layers below its own
(``tests/test_layers.py`` checks it):

* ``core/``: the runtime, processes, domains, waiting, names, conversions (rclpy and a few named extras);
* ``notebook/``: what only makes sense in Jupyter: the ``%ros2`` magics, quizzes, widgets;
* ``viz/``: the live computation graph and the course's diagrams;
* ``nodes/``: small idiomatic nodes that several chapters reuse;
* ``chapters/``: one module or package per chapter, with its demos, measurements and plots;
* ``checks/`` and ``solutions/``: the exercise checkers and the reference solutions
  (checkers never import solutions, so a student build can leave them out).
"""

from __future__ import annotations

__all__ = ["CourseError", "CourseRuntime", "WaitTimeout", "claim", "claim_timing", "get_runtime",
           "shutdown_runtime"]


def get_runtime(executor: str | None = None):
    """This kernel's ROS runtime, started on first use (see :mod:`course_helpers.core.runtime`).

    In a notebook it also makes the ``%ros2`` magics available, keeps ROS running through the
    interrupt button, and lets the runtime name the cell that added each node
    (:mod:`course_helpers.notebook.kernel`).
    """
    from course_helpers.core.console import in_jupyter_kernel
    from course_helpers.core.runtime import get_runtime as _get_runtime

    runtime = _get_runtime(executor)
    if in_jupyter_kernel():
        from course_helpers.notebook.kernel import set_up_once

        set_up_once(runtime)
    return runtime


def __getattr__(name: str):
    # Loaded on first use, so that a child process importing course_helpers.core.child
    # does not pay for rclpy before it needs it.
    if name in ("CourseError", "WaitTimeout"):
        from course_helpers.core import errors

        return getattr(errors, name)
    if name in ("CourseRuntime", "shutdown_runtime"):
        from course_helpers.core import runtime

        return getattr(runtime, name)
    if name in ("claim", "claim_timing"):  # a notebook's claims: one line each, with the verdict
        from course_helpers.core import verdict

        return getattr(verdict, name)
    raise AttributeError(f"module 'course_helpers' has no attribute {name!r}")
