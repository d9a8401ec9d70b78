"""What ``get_runtime()`` sets up in a notebook kernel, once: the ``%ros2`` magics, interrupts that
keep ROS (:mod:`.interrupts`), the cell each node comes from (:mod:`.cell_origins`), and one line
naming the other notebooks of this Jupyter server that run ROS (:mod:`course_helpers.core.other_kernels`)."""

from __future__ import annotations


def set_up_once(runtime) -> None:
    """Register the course's kernel hooks in the running IPython kernel and name the other notebooks
    that run ROS (the first call only)."""
    from IPython import get_ipython

    from course_helpers.core.other_kernels import notice, other_kernels
    from course_helpers.notebook import cell_origins, interrupts
    from course_helpers.notebook.magics import register_once

    shell = get_ipython()
    if shell is None:
        return
    if getattr(shell, "_course_kernel_set_up", False):
        return
    shell._course_kernel_set_up = True
    register_once()
    interrupts.install(shell, runtime)
    cell_origins.install(shell, runtime.origins)
    line = notice(other_kernels())
    if line:
        print(line, flush=True)
