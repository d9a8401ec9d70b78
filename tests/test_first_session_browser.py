"""A student's first session, from a fresh clone, in a real browser (issue 22).

The course is cloned into a temporary folder and started with its real command, ``make lab``, in a
pseudo-terminal as a student's shell would run it, with an empty working copy. The test then

1. reads the one line ``make lab`` prints, and opens its address in headless Chromium (Playwright,
   Debian's ``/usr/bin/chromium``): JupyterLab opens at notebook 00, shows no nbgrader menu, panel or
   button, marks the saved outputs as the reference run's, and its log holds no nbgrader message;
2. runs all of notebook 00: no cell shows an error, and no saved-output note is left;
3. (the textbook ``rclpy.spin`` and Interrupt: ``test_textbook_spin_and_interrupt_keep_the_nodes``
   below, skipped until the core's interrupt fix is merged);
4. opens the QoS lab beside a CPU-bound process and another course kernel running chapter 03's
   nodes, runs the preset "best-effort vs reliable under load" with its "Run both", and checks
   that reliable delivered every sample and that the lab says the machine was busy;
5. presses Ctrl-C in the terminal: ``make lab`` ends cleanly (exit 0, no "Interrupt" from make) and
   every kernel and its child processes are gone.

Screenshots: ``tests/artifacts/first_session_start.png`` (the start page) and
``tests/artifacts/first_session_lab_under_load.png`` (the QoS lab's panel under load).

The clone uses this checkout's ``.venv`` (``make lab VENV=...``, its install stamp taken as up to
date): a set-up from scratch is what ``make test-pythons`` proves, and would take minutes here.
"""

from __future__ import annotations

import fcntl
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import termios
import threading
import time

import psutil
import pytest

from course_helpers.core.waiting import poll_until
from tests.test_qos_lab_browser import CHROMIUM, CHROMIUM_ARGS, SETTINGS, _free_port

# About 2 minutes on a busy 2-core machine: JupyterLab twice, notebook 00, two lab runs under load.
pytestmark = [pytest.mark.browser, pytest.mark.timeout(600)]

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
VENV = os.path.join(REPO, ".venv")
ARTIFACTS = os.path.join(REPO, "tests", "artifacts")
NBGRADER_UI = ("Nbgrader", "Create Assignment", "Validate", "Formgrader")
REFERENCE_NOTE = "Saved output of the course's reference run"


class Terminal:
    """``make lab`` in a pseudo-terminal of its own (its controlling terminal), read in a thread."""

    def __init__(self, argv: list[str], cwd: str, env: dict):
        master, slave = os.openpty()

        def take_terminal():  # after setsid(): the pty becomes this session's controlling terminal
            fcntl.ioctl(0, termios.TIOCSCTTY, 0)

        self.process = subprocess.Popen(argv, cwd=cwd, env=env, stdin=slave, stdout=slave, stderr=slave,
                                        start_new_session=True, preexec_fn=take_terminal)
        os.close(slave)
        self.master, self.output = master, ""
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        while True:
            try:
                data = os.read(self.master, 4096)
            except OSError:
                return
            if not data:
                return
            self.output += data.decode(errors="replace")

    def press_ctrl_c(self) -> None:
        os.write(self.master, b"\x03")  # the terminal sends SIGINT to its foreground process group

    def close(self) -> None:
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGKILL)
            self.process.wait(timeout=10)
        self._reader.join(timeout=5)
        os.close(self.master)


@pytest.fixture
def fresh_clone(tmp_path):
    """A clone of this repository's committed state, a settings folder, and an empty working copy."""
    if not os.path.exists(CHROMIUM):
        pytest.skip(f"{CHROMIUM} is missing: install Debian's chromium (apt-get install chromium) or set "
                    "COURSE_CHROMIUM; Playwright must not download a browser")
    pytest.importorskip("playwright.sync_api", reason="playwright (PyPI) is not installed")
    if shutil.which("git") is None or shutil.which("make") is None:
        pytest.skip("git and make are needed to clone the course and run make lab")
    clone = tmp_path / "course"
    subprocess.run(["git", "clone", "--quiet", REPO, str(clone)], check=True, timeout=120)
    for name, values in SETTINGS.items():
        path = tmp_path / "settings" / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(values))
    return clone, tmp_path


def test_a_students_first_session(fresh_clone):
    from playwright.sync_api import sync_playwright

    clone, scratch = fresh_clone
    work, runtime = scratch / "work", scratch / "runtime"
    env = dict(os.environ)
    env.pop("ROS_DOMAIN_ID", None)  # each kernel reserves a domain of its own, as for a student
    env.pop("JUPYTER_CONFIG_PATH", None)
    env.update(JUPYTER_RUNTIME_DIR=str(runtime), JUPYTERLAB_SETTINGS_DIR=str(scratch / "settings"),
               JUPYTERLAB_WORKSPACES_DIR=str(scratch / "workspaces"), BROWSER="true")  # no browser to open
    stamp = os.path.join(VENV, ".course-installed")
    terminal = Terminal(["make", "lab", f"VENV={VENV}", f"WORK={work}", f"PORT={_free_port()}", "-o", stamp],
                        cwd=str(clone), env=env)
    os.makedirs(ARTIFACTS, exist_ok=True)
    hog = kernel = None
    try:
        # 1. One line with the address (token included) and how to stop.
        assert poll_until(lambda: "Ctrl-C" in terminal.output or terminal.process.poll() is not None, 180,
                          period=0.2), terminal.output
        lines = [line for line in terminal.output.splitlines() if line.startswith("Open http")]
        assert len(lines) == 1, terminal.output
        url = re.match(r"Open (http://\S+) in your browser", lines[0]).group(1)
        assert "/lab/tree/00_welcome.ipynb?token=" in url and str(work) in lines[0], lines[0]
        assert "Ctrl-C here to stop JupyterLab and shut its kernels down" in lines[0]
        print(terminal.output)
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            try:
                started = time.monotonic()
                _start_page(page, url)
                print(f"start page after {time.monotonic() - started:.0f} s")
                _run_all_of_00(page)
                print(f"notebook 00 ran after {time.monotonic() - started:.0f} s")
                hog, kernel = _busy_machine()
                _lab_under_load(page)
                print(f"the lab ran under load after {time.monotonic() - started:.0f} s")
            except Exception:
                page.screenshot(path=os.path.join(ARTIFACTS, "first_session_failure.png"))
                raise
            finally:
                browser.close()
        log = (work / ".lab.log").read_text(errors="replace")
        assert "nbgrader" not in log.lower() and "subdirectory" not in log, "nbgrader spoke in the log"
        # 5. Ctrl-C in the terminal: the server shuts its kernels (and their children) down, make ends well.
        server = psutil.Process(json.loads(next(runtime.glob("jpserver-*.json")).read_text())["pid"])
        kernels = server.children(recursive=True)
        assert len(kernels) >= 2, kernels  # 00's and 08b's kernels (and the lab's processes, if any)
        terminal.press_ctrl_c()
        terminal.process.wait(timeout=90)
        print(terminal.output[-400:])
        assert terminal.process.returncode == 0, terminal.output
        assert "JupyterLab stopped." in terminal.output and "Interrupt" not in terminal.output
        assert not [p for p in kernels if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]
    finally:
        if hog is not None:
            hog.kill()
            hog.wait()
        if kernel is not None:
            kernel.shutdown()
        terminal.close()


def _start_page(page, url: str) -> None:
    """The address opens notebook 00, with no nbgrader UI and the saved outputs marked."""
    page.goto(url, timeout=90_000)
    page.wait_for_selector(".jp-Notebook .jp-Cell", timeout=90_000)
    page.locator(".jp-StatusBar-Item", has_text="Idle").first.wait_for(timeout=120_000)
    assert page.locator(".lm-TabBar-tab.lm-mod-current", has_text="00_welcome.ipynb").count() >= 1
    page.locator(".jp-RenderedMarkdown", has_text=REFERENCE_NOTE).first.wait_for(timeout=10_000)
    page.screenshot(path=os.path.join(ARTIFACTS, "first_session_start.png"))
    assert_no_nbgrader_ui(page)


def assert_no_nbgrader_ui(page) -> None:
    """No nbgrader menu, side panel or toolbar button anywhere in the page."""
    menus = page.locator("#jp-MainMenu .lm-MenuBar-itemLabel").all_inner_texts()
    assert menus and "Nbgrader" not in menus, menus
    labels = page.evaluate("""() => [...document.querySelectorAll(
        '.lm-TabBar-tab, .jp-Toolbar-item, .jp-ToolbarButtonComponent, [title], [aria-label]')]
        .map(e => [e.getAttribute('title'), e.getAttribute('aria-label'), e.textContent].join(' '))""")
    found = sorted({word for label in labels for word in NBGRADER_UI if word.lower() in label.lower()})
    assert not found, f"nbgrader UI in the student's JupyterLab: {found}"


def _run_all_of_00(page) -> None:
    """Run → Run All Cells; every code cell runs, none shows an error, no saved-output note is left."""
    page.locator("#jp-MainMenu .lm-MenuBar-itemLabel", has_text=re.compile(r"^Run$")).click()
    page.locator(".lm-Menu-itemLabel", has_text=re.compile(r"^Run All Cells$")).click()
    prompts = page.locator(".jp-CodeCell .jp-InputPrompt")

    def all_ran() -> bool:
        texts = prompts.all_inner_texts()
        return bool(texts) and all(re.fullmatch(r"\[\d+\]:", t.strip()) for t in texts)

    assert poll_until(all_ran, 180, period=0.5), prompts.all_inner_texts()
    errors = page.locator('[data-mime-type="application/vnd.jupyter.error"]')
    assert errors.count() == 0, errors.all_inner_texts()
    assert page.locator(".jp-RenderedMarkdown", has_text=REFERENCE_NOTE).count() == 0  # every output is live


def _busy_machine():
    """A CPU-bound process and another course kernel with chapter 03's nodes (as in test_qos_lab_busy)."""
    import nbformat

    from tests.kernel_session import KernelSession
    from tests.test_qos_lab_busy import CH03_CELLS, SENSOR_ARRAY

    notebook = nbformat.read(os.path.join(REPO, "notebooks", "03_topics.ipynb"), as_version=4)
    sources = {cell.get("id"): cell.source for cell in notebook.cells}
    hog = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    kernel = KernelSession(cwd=os.path.join(REPO, "notebooks"))
    cell, cut = SENSOR_ARRAY
    for code in [sources[c] for c in CH03_CELLS] + [sources[cell].split(cut)[0]]:
        _out, error = kernel.run(code, timeout=120)
        assert error is None, f"chapter 03's cell failed: {error}\n{code}"
    return hog, kernel


def _lab_under_load(page) -> None:
    """08b's lab: the preset's Run both on a busy machine; reliable delivers all, the lab says busy."""
    page.locator(".jp-DirListing-item", has_text="08b_qos_lab.ipynb").dblclick()  # from the file browser
    page.locator(".lm-TabBar-tab.lm-mod-current", has_text="08b_qos_lab.ipynb").wait_for(timeout=90_000)
    notebook = page.locator(".jp-NotebookPanel:visible")
    notebook.locator(".jp-CodeCell").first.wait_for(timeout=90_000)
    for text in ("rt = get_runtime()", "lab = qos_lab()"):  # the runtime, then the lab's cell
        cell = notebook.locator(".jp-CodeCell").filter(has_text=text).first
        cell.locator(".jp-InputArea-editor").click()
        page.keyboard.press("Shift+Enter")
        cell.locator(".jp-InputPrompt", has_text=re.compile(r"\[\d+\]")).wait_for(timeout=90_000)
    panel = notebook.locator(".qos-lab").first
    panel.wait_for(timeout=60_000)
    panel.locator("button", has_text="best-effort vs reliable under load").click()
    run_both = panel.locator("button").filter(has_text=re.compile(r"^\s*Run both\s*$"))
    run_both.click()
    status = panel.locator(".qos-lab-status")
    status.filter(has_text=re.compile(r"^\s*(Done|Stopped|The experiment failed)")).first.wait_for(
        timeout=240_000)
    panel.scroll_into_view_if_needed()
    panel.screenshot(path=os.path.join(ARTIFACTS, "first_session_lab_under_load.png"))
    text = status.inner_text()
    print(f"lab under load: {text}\n{panel.locator('.qos-lab-machine').inner_text()}")
    assert text.startswith("Done.") and "NOT FINISHED" not in text, text
    assert "reliable, 1 MiB @ 400 Hz: delivered 300 of 300 sent, nothing lost" in text, text
    assert "This machine was busy during the run" in panel.locator(".qos-lab-machine").inner_text()
    rows = panel.locator("table.qos-lab-results tbody tr")
    delivered = [int(rows.nth(i).locator("td").nth(3).inner_text()) for i in range(rows.count())]
    assert len(delivered) == 2 and delivered[1] >= delivered[0], delivered  # reliable never below


@pytest.mark.skip(reason="needs the core's interrupt fix (issue 22, item 2), which is not merged yet")
def test_textbook_spin_and_interrupt_keep_the_nodes():
    """The place for step 3 of the first session, once interrupts keep ROS (issue 22, item 2).

    After notebook 00 has run: paste the textbook's ``rclpy.init(); n = Node('x'); rclpy.spin(n)``
    into a new cell, run it and press Interrupt; the cell must show a one-line KeyboardInterrupt (no
    internal traceback), ``rt.nodes()`` and the process list must still hold the chapter's nodes and
    children, and the next course cell must pass. Save ``tests/artifacts/first_session_interrupt.png``.
    """
