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
        show_notice(line)


def show_notice(line: str):
    """Display the other-kernels notice ``line`` with a button that shuts those kernels down
    (:func:`course_helpers.core.kernel_shutdown.shutdown_other_kernels`) and says what it did. The
    saved output is the line. Returns the button."""
    import html

    import ipywidgets as w
    from IPython.display import display

    from course_helpers.core.kernel_shutdown import shutdown_other_kernels
    from course_helpers.notebook.widget_errors import owned

    button = w.Button(description="Shut them down", icon="power-off", button_style="warning",
                      tooltip="rt.shutdown_other_kernels(): this user's other course kernels of this server")
    said = w.HTML()

    def shut_down(_button) -> None:
        button.disabled = True
        said.value = "<i>shutting them down ...</i>"
        _done, result = shutdown_other_kernels()
        said.value = f"<span class='course-shutdown-result'>{html.escape(result)}</span>"

    button.on_click(shut_down)
    box = w.VBox([w.HTML(f"<span style='color:#8a5a00'>{html.escape(line)}</span>"), w.HBox([button, said])])
    box.add_class("course-other-kernels")
    view = owned(box, "the other kernels' notice")._repr_mimebundle_()
    display({"text/plain": line, "text/html": f"<p>{html.escape(line)}</p>",
             **{k: v for k, v in view.items() if "widget-view" in k}}, raw=True)
    return button
