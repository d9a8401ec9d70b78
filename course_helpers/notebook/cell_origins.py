"""Which notebook cell is running, for the runtime to remember which cell added each node and child.

When the runtime heals after an outside shutdown, its notice names the cells to run again
(:mod:`course_helpers.core.healing`). Core knows nothing of cells; :func:`install` gives the runtime
a way to ask. The answer comes from the request the kernel is serving (``Kernel.get_parent()``: the
cell's code) and IPython's input history (the prompt number a student sees next to it), so it does
not depend on when IPython counts a cell.
"""

from __future__ import annotations

LABEL_CHARS = 40  # of the cell's first line of code, in a label


def install(shell, origins) -> None:
    """Let ``origins`` (the runtime's) ask which cell is running."""
    origins.where_called = lambda: running_cell(shell)


def running_cell(shell) -> str | None:
    """The label of the cell the kernel is running (:func:`cell_label`), or None when no cell runs
    (a widget's callback, a message from the frontend)."""
    code = shell.kernel.get_parent().get("content", {}).get("code")
    if not code:
        return None
    history = shell.history_manager.input_hist_raw  # cell N's source at index N, stored before it runs
    prompt = len(history) - 1 if history and history[-1].rstrip() == code.rstrip() else None
    return cell_label(prompt, code)


def cell_label(execution_count: int | None, source: str) -> str:
    """'In [5] "listener = rt.add(Listener)"': the prompt a student sees and the cell's first line of
    code (prompts change when cells run again; the line does not). Without a prompt (a cell run
    without history, as nbval does): 'the cell "..."'."""
    lines = [line.strip() for line in source.splitlines()]
    first = next((line for line in lines if line and not line.startswith(("#", "%"))), "")
    if len(first) > LABEL_CHARS:
        first = first[:LABEL_CHARS - 1] + "…"
    prompt = f"In [{execution_count}]" if execution_count is not None else "the cell"
    return f'{prompt} "{first}"' if first else prompt
