"""A course widget's callback error shows as one line in its own cell (issue 31, items 1 and 2).

A real kernel runs notebook 00's cells up to its rate slider, then the cell that removes every node
(``rt.remove_all()``), as "Run All" does. The test then sends the kernel what JupyterLab sends when a
student drags the slider (a ``comm_msg`` "update" on the widget's comm) and when a student presses a
button (a "custom" click). The slider's callback drives the destroyed talker: the error must appear in
the slider's own error line, as one line that names the cell to run again, and nothing may go to
the kernel's other outputs (what JupyterLab's log console would show). A button whose callback
raises shows its error the same way; the next message handled without an error clears the line.
"""

from __future__ import annotations

import os

import nbformat

from .kernel_session import KernelSession

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# 00's cells: the runtime, the Talker and Listener classes, the chapter's talker, the slider, remove_all
CELLS = ("d4dc3b8e", "79ee9b1e", "86b3c053", "ba0f9e24", "4cca0f94")
BUTTON = """
import ipywidgets as widgets
from course_helpers.notebook.records import show_with_record

def fails(_button):
    raise ValueError('the sensor is unplugged')

button = widgets.Button(description='press')
button.on_click(fails)
shown = show_with_record(button, 'a failing button', 'a button')
"""
ERROR_LINE = ("from course_helpers.notebook import widget_errors\n"
              "print([ref().error_line.value for ref in widget_errors._owners if ref() is not None])")


def _browser_message(kernel: KernelSession, widget: str, data: dict) -> list[dict]:
    """Send the kernel a comm message for the widget named ``widget`` in the kernel, as JupyterLab does;
    return every iopub message the kernel sent while handling it."""
    out, error = kernel.run(f"print({widget}.comm.comm_id)")
    assert error is None, error
    client = kernel.client
    message = client.session.msg("comm_msg", {"comm_id": out.strip(), "data": data})
    client.shell_channel.send(message)
    seen = []
    while True:
        reply = client.get_iopub_msg(timeout=30)
        if reply["parent_header"].get("msg_id") != message["header"]["msg_id"]:
            continue
        seen.append(reply)
        if reply["msg_type"] == "status" and reply["content"]["execution_state"] == "idle":
            return seen


def _noise(messages: list[dict]) -> list:
    """What the kernel sent besides widget state: errors and printed text (the log console's)."""
    return [(m["msg_type"], m["content"]) for m in messages
            if m["msg_type"] in ("error", "stream", "display_data", "execute_result")]


def _error_lines(kernel: KernelSession) -> list[str]:
    out, error = kernel.run(ERROR_LINE)
    assert error is None, error
    return eval(out)  # a list of strings the kernel printed


def test_a_slider_whose_node_a_later_cell_destroyed_says_so_in_its_cell():
    notebook = nbformat.read(os.path.join(REPO, "notebooks", "00_welcome.ipynb"), as_version=4)
    sources = {cell.get("id"): cell.source for cell in notebook.cells}
    kernel = KernelSession(cwd=os.path.join(REPO, "notebooks"))
    try:
        counts = {}
        for cell in CELLS:
            _out, error = kernel.run(sources[cell], timeout=60)
            assert error is None, f"00's cell {cell} failed: {error}"
            counts[cell] = kernel.execution_count
        messages = _browser_message(kernel, "rate", {"method": "update", "state": {"value": 7.0},
                                                     "buffer_paths": []})
        assert _noise(messages) == [], _noise(messages)
        lines = _error_lines(kernel)
        slider_cell = counts["ba0f9e24"]
        print(lines)
        assert len(lines) == 1 and lines[0].count("\n") == 0, lines
        assert "rate slider: the node it drives was destroyed by a later cell" in lines[0], lines
        assert f"run cell [{slider_cell}] again" in lines[0], (slider_cell, lines)
        out, _ = kernel.run("print(rate.value)")
        assert out.strip() == "7.0"  # the widget's state is what the browser shows

        # A button whose callback raises: one line in its cell, nothing elsewhere.
        _out, error = kernel.run(BUTTON)
        assert error is None, error
        messages = _browser_message(kernel, "button", {"method": "custom", "content": {"event": "click"}})
        assert _noise(messages) == [], _noise(messages)
        lines = _error_lines(kernel)
        assert "a failing button: ValueError: the sensor is unplugged" in lines[-1], lines
        # the cell runs again with a talker: the slider works and its line clears
        _out, error = kernel.run(sources["86b3c053"])
        assert error is None, error
        _out, error = kernel.run("talker = rt.add(Talker)")
        assert error is None, error
        messages = _browser_message(kernel, "rate", {"method": "update", "state": {"value": 10.0},
                                                     "buffer_paths": []})
        assert _noise(messages) == [], _noise(messages)
        out, _ = kernel.run("print(talker.timer.timer_period_ns)")
        assert out.strip() == str(int(1e9 / 10.0)), out
        assert _error_lines(kernel)[0] == "", "the slider's line was not cleared"
    finally:
        kernel.shutdown()
