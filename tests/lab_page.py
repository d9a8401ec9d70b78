"""A student's clicks and keys in JupyterLab's page, for the browser tests (Playwright).

Cells are run as a student runs them, with a click in the editor and Shift+Enter, but only once the
status bar shows the notebook's own kernel idle and the cell's editor has the focus in edit mode. A
freshly opened notebook renders its cells while it still has no kernel ("No Kernel | Initializing");
a Shift+Enter then makes JupyterLab start a kernel of its own beside the one being started, or ask
which to use, and may leave the cell unrun. A Shift+Enter without the focus runs another cell or none.
"""

from __future__ import annotations

import re

from course_helpers.core.waiting import poll_until

from .browsers import HANG_MS, artifact

NBGRADER_UI = ("Nbgrader", "Create Assignment", "Validate", "Formgrader")


def menu(page, menu_name: str, item: str) -> None:
    """Choose ``item`` in the main menu ``menu_name`` (e.g. 'Run', 'Run All Cells')."""
    page.locator("#jp-MainMenu .lm-MenuBar-item", has_text=re.compile(rf"^\s*{menu_name}\s*$")).click()
    page.locator(".lm-Menu-item", has_text=item).first.click()


def assert_no_nbgrader_ui(page) -> None:
    """No nbgrader menu, side panel or toolbar button anywhere in the page."""
    menus = page.locator("#jp-MainMenu .lm-MenuBar-itemLabel").all_inner_texts()
    assert menus and "Nbgrader" not in menus, menus
    labels = page.evaluate("""() => [...document.querySelectorAll(
        '.lm-TabBar-tab, .jp-Toolbar-item, .jp-ToolbarButtonComponent, [title], [aria-label]')]
        .map(e => [e.getAttribute('title'), e.getAttribute('aria-label'), e.textContent].join(' '))""")
    found = sorted({word for label in labels for word in NBGRADER_UI if word.lower() in label.lower()})
    assert not found, f"nbgrader UI in the student's JupyterLab: {found}"


def new_cell(page, notebook, code: str):
    """An empty code cell at the end of the notebook (a new one if needed), ``code`` pasted in."""
    cells = notebook.locator(".jp-Notebook .jp-Cell")
    count = cells.count()
    cell = cells.nth(count - 1)  # by position: the last cell changes when Shift+Enter adds one
    code_cell = "jp-CodeCell" in cell.get_attribute("class")
    if not code_cell or cell.locator(".jp-InputArea-editor").inner_text().strip():
        cell.locator(".jp-InputPrompt").first.click()  # selects it, in command mode
        notebook.locator(".jp-Notebook.jp-mod-commandMode").wait_for(timeout=HANG_MS)
        page.keyboard.press("b")  # insert a cell below
        cell = cells.nth(count)
        cell.wait_for(timeout=HANG_MS)
    cell.locator(".jp-InputArea-editor").click()
    cell.locator(".jp-InputArea-editor.jp-mod-focused").wait_for(timeout=HANG_MS)
    page.keyboard.insert_text(code)  # as a paste: no auto-indent or closing brackets
    assert cell.locator(".jp-InputArea-editor").inner_text().split() == code.split(), "the paste went wrong"
    return cell


def run_cell(page, notebook, cell, finished: bool = True):
    """Shift+Enter in ``cell`` as a student does, once that is sure to run it; returns the cell.

    Waits first for the notebook's own kernel to be idle (a Shift+Enter while the notebook has no
    kernel yet may start a second one, ask which to use, or leave the cell unrun) and for the
    cell's editor to have the focus in edit mode. Then waits for the cell to start (``[*]``), and
    with ``finished`` for its new execution count.
    """
    wait_for_its_kernel(page)
    prompt = cell.locator(".jp-InputPrompt").first
    shown_before = prompt.inner_text().strip()
    cell.locator(".jp-InputArea-editor").click()
    cell.locator(".jp-InputArea-editor.jp-mod-focused").wait_for(timeout=HANG_MS)
    notebook.locator(".jp-Notebook.jp-mod-editMode").wait_for(timeout=HANG_MS)
    page.keyboard.press("Shift+Enter")
    dialog = page.locator(".jp-Dialog")

    def started() -> bool:
        assert dialog.count() == 0, f"JupyterLab asks instead of running: {dialog.all_inner_texts()}"
        return prompt.inner_text().strip() not in ("", "[ ]:", shown_before)

    assert poll_until(started, 30, period=0.1), f"the cell did not start: {prompt.inner_text()!r}"
    if finished:
        def ended() -> bool:
            text = prompt.inner_text().strip()
            return bool(re.fullmatch(r"\[\d+\]:", text)) and text != shown_before

        assert poll_until(ended, 120, period=0.2), f"the cell did not end: {prompt.inner_text()!r}"
    return cell


def red_outputs(page) -> list[str]:
    """The outputs JupyterLab shows in red: errors (rendered as their traceback) and stderr."""
    red = page.locator('.jp-OutputArea-output[data-mime-type="application/vnd.jupyter.stderr"]')
    return red.all_inner_texts()


def wait_for_its_kernel(page) -> None:
    """Until the status bar shows the current notebook's own kernel, connected and idle.

    (The toolbar's execution indicator says "idle" before the notebook has a kernel at all.)
    """
    name = page.locator("#jp-main-dock-panel .lm-TabBar-tab.lm-mod-current .lm-TabBar-tabLabel").inner_text()
    bar = page.locator("#jp-main-statusbar")

    def ready() -> bool:
        text = bar.inner_text()
        return name.strip() in text and re.search(r"\|\s*Idle\b", text) is not None

    assert poll_until(ready, 120, period=0.2), f"{name}'s kernel is not idle: {bar.inner_text()!r}"


def outputs(cell) -> str:
    """The text of a cell's outputs (its node consoles included)."""
    return "\n".join(cell.locator(".jp-OutputArea-output").all_inner_texts())


def wait_until_lab_finished(panel) -> None:
    """Wait for the end of 08b's lab run in ``panel``: its last status ('Done', 'Stopped' or a failure),
    then the Run button enabled again, which the panel does last, after its machine note and after
    replacing its static record. That replacement makes JupyterLab draw the widget anew, so an element
    found before it is gone after it. :data:`HANG_MS` only ends a hang."""
    last = re.compile(r"^\s*(Done|Stopped|The experiment failed)")
    panel.locator(".qos-lab-status").filter(has_text=last).first.wait_for(timeout=HANG_MS)
    run = panel.locator("button").filter(has_text=re.compile(r"^\s*Run( both)?\s*$")).first
    assert poll_until(run.is_enabled, HANG_MS / 1000, period=0.1), "the Run button stayed disabled"


def screenshot_widget(widget, name: str) -> None:
    """Save a widget's picture as ``tests/artifacts/<name>``. A widget that JupyterLab draws anew meanwhile
    (its output's display was updated) detaches the element; it is then found again. The picture is
    for readers of the artifacts, not a check."""
    for attempt in range(3):
        try:
            widget.screenshot(path=artifact(name), timeout=HANG_MS)
            return
        except Exception as error:  # playwright's Error: "Element is not attached to the DOM"
            if "not attached" not in str(error) or attempt == 2:
                raise
