"""A live indicator for a build that takes a while: ``ws.build(progress=build_progress())``."""

from __future__ import annotations

import time
from collections.abc import Callable

from course_helpers.core.console import in_jupyter_kernel


def build_progress(title: str = "colcon build") -> Callable[[str], None] | None:
    """A ``progress=`` callback for ``Workspace.build`` and ``build_interface_package``.

    Args:
        title: what the indicator calls the build.

    Returns:
        In a notebook: a function that takes each line the build prints (and 'done' or
        'FAILED' at the end) and shows a small widget with a bar, the elapsed time and the
        latest line. Elsewhere: None (no output).
    """
    if not in_jupyter_kernel():
        return None
    import ipywidgets as widgets
    from IPython.display import display

    bar = widgets.FloatProgress(value=0, min=0, max=1, bar_style="info",
                                layout=widgets.Layout(width="260px"))
    label = widgets.Label(value=f"{title}: starting")

    class ProgressBox(widgets.HBox):
        def __repr__(self) -> str:  # plain-text form: fixed, so notebook outputs stay comparable
            return f"<{title} progress>"

    display(ProgressBox([bar, label]))
    started = time.monotonic()

    def update(line: str) -> None:
        elapsed = time.monotonic() - started
        bar.value = min(0.95, elapsed / (elapsed + 5.0))  # creeps towards the end, never claims done
        if line in ("done", "FAILED"):
            bar.value = 1.0
            bar.bar_style = "success" if line == "done" else "danger"
        shown = line if len(line) < 90 else line[:87] + "..."
        label.value = f"{title} ({elapsed:.0f} s): {shown}"

    return update
