"""Every notebook as a student meets it in JupyterLab: Run All, then every slider and button once (issue 31).

For each chapter a real JupyterLab (one per test worker) opens the notebook in headless Chromium
(Debian's, driven by Playwright), which starts a fresh kernel, and runs Run → Run All Cells. Every
code cell must run, and none may show a traceback. Then every slider of the page is moved one step
with the keyboard, and every enabled button is pressed once, as a student trying the widgets would.
Afterwards:

* JupyterLab's log console (where an output with no cell to go to ends up) holds no error: every
  widget callback's error went to its own cell (``course_helpers/notebook/widget_errors.py``);
* an error a widget shows in its cell is the designed message: one line under the widget;
* each slider's readout shows its widget's value (00's rate slider after Run All: 20.00, the value
  the next cell set).

Long (every notebook, run as a student runs it): not part of ``make test``; ``make test-browser`` runs
it (and ``.ci/run`` after ``make test``). Screenshots of 00's slider after Run All and after it was moved
go to ``tests/artifacts/``.
"""

from __future__ import annotations

import glob
import os
import re
import time

import pytest

from course_helpers.core.waiting import poll_until

from .browsers import HANG_MS, artifact, browser_page, require_chromium
from .lab_page import menu, red_outputs, run_cell, wait_for_its_kernel
from .servers import jupyter_lab

pytestmark = [pytest.mark.browser, pytest.mark.run_all, pytest.mark.timeout(900)]

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NOTEBOOKS = sorted(os.path.basename(p) for p in glob.glob(os.path.join(REPO, "notebooks", "*.ipynb")))
RUN_ALL_TIMEOUT_S = 420  # the longest chapters take about two minutes on a busy 2-core machine
ERROR_LINE = ".course-widget-error"
LOG_ERRORS = re.compile(r"Traceback|Error|Exception")


@pytest.fixture(scope="module")
def lab():
    require_chromium()
    with jupyter_lab(options=("--LabApp.expose_app_in_browser=True",)) as running:
        yield running


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_run_all_then_every_slider_and_button(lab, name):
    stem = name.removesuffix(".ipynb")
    with browser_page(height=1000, on_failure=f"run_all_{stem}_failure.png") as page:
        started = time.monotonic()
        # a workspace of its own: JupyterLab reopens no notebook of an earlier test (nor starts its kernel)
        page.goto(lab.url(f"lab/workspaces/{stem}/tree/{name}"), timeout=HANG_MS)
        notebook = page.locator(".jp-NotebookPanel:visible")
        notebook.locator(".jp-CodeCell").first.wait_for(timeout=HANG_MS)
        wait_for_its_kernel(page)
        _clear_outputs(page, notebook)  # every prompt, output and error seen below is this run's
        menu(page, "Run", "Run All Cells")
        _wait_until_every_cell_ran(page, notebook)
        ran = time.monotonic() - started
        shown = "\n".join(notebook.locator(".jp-OutputArea-output").all_inner_texts())
        assert "Traceback (most recent call last)" not in shown, shown[-3000:]
        assert not [text for text in red_outputs(page) if "Traceback" in text or "Error" in text], \
            red_outputs(page)
        if name == "00_welcome.ipynb":
            _slider_in_step(page, notebook, "rate (Hz)", "20.00", "slider_after_run_all.png")
        moved, pressed = _move_every_slider(page, notebook), _press_every_button(page, notebook)
        _wait_until_quiet(page, notebook)
        if name == "00_welcome.ipynb":
            _designed_error_under(notebook, "rate (Hz)")
            _screenshot_cell(notebook, "rate (Hz)", "slider_error_line.png")
        errors = notebook.locator(ERROR_LINE).all_inner_texts()
        for line in errors:  # the designed message: one line that says what happened
            assert line.count("\n") == 0 and "Traceback" not in line, line
        log = _log_console(page)
        summary = (f"{name}: ran in {ran:.0f} s; {moved} sliders moved, {pressed} buttons pressed; "
                   f"{len(errors)} widget error line(s): {errors}; log console: {log[:300]!r}")
        print(summary)
        with open(artifact(f"run_all_{stem}.txt"), "w", encoding="utf-8") as out:  # for the record
            out.write(summary + "\n")
        assert not LOG_ERRORS.search(log), f"JupyterLab's log console holds an error:\n{log[-3000:]}"
    for session in lab.api("/api/sessions"):  # the next notebook starts on a free machine
        if session["path"].endswith(name):
            lab.api(f"/api/sessions/{session['id']}", method="DELETE", timeout=60)


def _clear_outputs(page, notebook) -> None:
    """Edit → Clear Outputs of All Cells: the saved notebook's prompts are numbered already."""
    menu(page, "Edit", "Clear Outputs of All Cells")
    prompts = notebook.locator(".jp-CodeCell .jp-InputPrompt")
    assert poll_until(lambda: not any(re.search(r"\d", t) for t in prompts.all_inner_texts()), 30,
                      period=0.2), "the outputs were not cleared"


def _wait_until_every_cell_ran(page, notebook) -> None:
    prompts = notebook.locator(".jp-CodeCell .jp-InputPrompt")

    def every_cell_ran() -> bool:
        texts = prompts.all_inner_texts()
        return bool(texts) and all(re.fullmatch(r"\[\d+\]:", t.strip()) for t in texts)

    if not poll_until(every_cell_ran, RUN_ALL_TIMEOUT_S, period=1.0):
        waiting = [t for t in prompts.all_inner_texts() if not re.fullmatch(r"\[\d+\]:", t.strip())]
        raise AssertionError(f"not every cell ran within {RUN_ALL_TIMEOUT_S} s: {len(waiting)} left, "
                             f"{red_outputs(page)[-3:]}")


def _sliders(notebook):
    return notebook.locator(".jp-OutputArea .widget-slider:visible")


def _move_every_slider(page, notebook) -> int:
    """Each visible slider one step up (its handle focused, ArrowRight), as a student's key press."""
    count = _sliders(notebook).count()
    for index in range(count):
        slider = _sliders(notebook).nth(index)
        handle = slider.locator(".noUi-handle")
        if handle.count() == 0 or slider.locator(".noUi-target[disabled]").count():
            continue
        handle.first.scroll_into_view_if_needed()
        readout = slider.locator(".widget-readout")
        before = readout.first.inner_text() if readout.count() else None
        for key in ("ArrowRight", "ArrowLeft"):  # one step up, or down from the top of the range
            handle.first.press(key)
            if before is None or poll_until(lambda r=readout, b=before: r.first.inner_text() != b, 3,
                                            period=0.1):
                break
    return count


def _press_every_button(page, notebook) -> int:
    """Every enabled, visible button of the outputs once (re-found by position: outputs re-render)."""
    buttons = notebook.locator(".jp-OutputArea button.jupyter-button:visible")
    pressed, index = 0, 0
    while index < buttons.count():
        button = buttons.nth(index)
        index += 1
        try:
            if button.is_disabled():
                continue
            button.scroll_into_view_if_needed(timeout=5_000)
            button.click(timeout=5_000)
            pressed += 1
        except Exception as error:  # a button that a press before it removed or re-rendered
            if "not attached" not in str(error) and "Timeout" not in str(error):
                raise
    return pressed


def _wait_until_quiet(page, notebook) -> None:
    """Until a run the presses started (the QoS lab's) has ended and the kernel is idle."""
    status = notebook.locator(".qos-lab-status")
    if status.count():
        stop = notebook.locator(".qos-lab button.jupyter-button", has_text=re.compile(r"^\s*Stop\s*$"))
        poll_until(lambda: stop.first.is_disabled(), 240, period=1.0)
    wait_for_its_kernel(page)


def _cell_with_slider(notebook, description: str):
    return notebook.locator(".jp-CodeCell").filter(
        has=notebook.page.locator(".widget-slider", has_text=description)).first


def _slider_in_step(page, notebook, description: str, value: str, picture: str) -> None:
    """The slider shows the value its widget holds (set by a later cell during Run All)."""
    readout = notebook.locator(".widget-slider", has_text=description).first.locator(".widget-readout")
    assert poll_until(lambda: readout.inner_text().strip() == value, 10, period=0.2), readout.inner_text()
    _screenshot_cell(notebook, description, picture)


def _designed_error_under(notebook, description: str) -> None:
    cell = _cell_with_slider(notebook, description)
    line = cell.locator(ERROR_LINE)
    assert poll_until(lambda: line.count() == 1, 20, period=0.2), "the slider's error line did not appear"
    text = line.inner_text()
    assert re.search(r"the node it drives was destroyed by a later cell .*: run cell \[\d+\] again", text), \
        text


def _screenshot_cell(notebook, description: str, picture: str) -> None:
    cell = _cell_with_slider(notebook, description)
    cell.scroll_into_view_if_needed()
    cell.screenshot(path=artifact(picture))


def _log_console(page) -> str:
    """The text of JupyterLab's log console for the current notebook, once it has drawn every entry.

    The panel draws the entries its log already holds after it appears. The sentinel is the panel's own
    Add Checkpoint: it appends a rule to this notebook's log, after every entry already there, and the
    panel draws entries in order, so once the rule shows, every earlier entry shows too."""
    commands = "window.jupyterapp.commands"
    page.evaluate(f"() => {commands}.execute('logconsole:open', {{insertMode: 'split-bottom'}})")
    panel = page.locator(".jp-LogConsolePanel")
    panel.first.wait_for(timeout=HANG_MS)
    # enabled once the panel shows a notebook's log (its source is set)
    page.wait_for_function(f"() => {commands}.isEnabled('logconsole:add-checkpoint')", timeout=HANG_MS)
    page.evaluate(f"() => {commands}.execute('logconsole:add-checkpoint')")
    panel.locator(".jp-OutputArea-output hr").last.wait_for(timeout=HANG_MS)
    return "\n".join(panel.locator(".jp-OutputArea-output").all_inner_texts())


def test_the_notice_button_and_the_labs_progress_beside_another_kernel(lab):
    """03's kernel runs ROS; 08b then names it in the other-kernels notice, with a button, and its lab
    warns before a run and counts while it goes; the notice's button shuts 03's kernel down."""
    with browser_page(height=1100, on_failure="busy_lab_failure.png") as page:
        page.goto(lab.url("lab/workspaces/busy/tree/03_topics.ipynb"), timeout=HANG_MS)
        notebook = page.locator(".jp-NotebookPanel:visible")
        notebook.locator(".jp-CodeCell").first.wait_for(timeout=HANG_MS)
        wait_for_its_kernel(page)
        _clear_outputs(page, notebook)
        run_cell(page, notebook, notebook.locator(".jp-CodeCell").filter(has_text="rt = get_runtime()").first)
        page.goto(lab.url("lab/workspaces/busy/tree/08b_qos_lab.ipynb"), timeout=HANG_MS)
        page.locator(".lm-TabBar-tab.lm-mod-current", has_text="08b_qos_lab.ipynb").wait_for(timeout=HANG_MS)
        notebook = page.locator(".jp-NotebookPanel:visible")
        notebook.locator(".jp-CodeCell").first.wait_for(timeout=HANG_MS)
        wait_for_its_kernel(page)
        _clear_outputs(page, notebook)
        first = notebook.locator(".jp-CodeCell").filter(has_text="rt = get_runtime()").first
        run_cell(page, notebook, first)
        notice = first.locator(".course-other-kernels")
        notice.wait_for(timeout=HANG_MS)
        assert "03_topics.ipynb" in notice.inner_text(), notice.inner_text()
        first.screenshot(path=artifact("notice_button.png"))
        run_cell(page, notebook, notebook.locator(".jp-CodeCell").filter(has_text="lab = qos_lab()").first)
        panel = notebook.locator(".qos-lab").first
        panel.wait_for(timeout=HANG_MS)
        panel.locator("button", has_text="depth 1 vs 100, slow subscriber").click()
        panel.locator("button").filter(has_text=re.compile(r"^\s*Run both\s*$")).click()
        warning = panel.locator(".qos-lab-busy")
        warning.wait_for(timeout=HANG_MS)
        assert "Before this run, this machine is" in warning.inner_text(), warning.inner_text()
        progress = panel.locator(".qos-lab-progress")
        lines: list[str] = []

        def counting() -> bool:
            text = progress.inner_text() if progress.count() else ""
            if text and (not lines or lines[-1] != text):
                lines.append(text)
            if len(lines) == 4:
                panel.screenshot(path=artifact("lab_progress.png"))
            return "s in all" in text

        assert poll_until(counting, HANG_MS / 1000, period=0.1), lines
        print("progress lines seen in the browser:", lines)
        running = [line for line in lines if " s so far" in line]
        assert len(running) >= 3, lines  # rewritten while the runs went
        assert any(re.search(r"\d+ sent and \d+ delivered", line) for line in running), lines
        notice.locator("button", has_text="Shut them down").click()
        said = notice.locator(".course-shutdown-result")
        said.wait_for(timeout=HANG_MS)
        print(said.inner_text())
        assert said.inner_text().startswith("[course] Shut down 1 other course kernel of this Jupyter server "
                                            "(03_topics.ipynb)"), said.inner_text()
        first.screenshot(path=artifact("notice_after_the_button.png"))
    for session in lab.api("/api/sessions"):
        lab.api(f"/api/sessions/{session['id']}", method="DELETE", timeout=60)
