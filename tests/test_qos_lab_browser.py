"""The QoS lab (chapter 08) in a real browser: JupyterLab + headless Chromium driven by Playwright.

Starts JupyterLab on a free localhost port with a random token, opens
``notebooks/08b_qos_lab.ipynb``, runs the lab cell (tagged ``qos-lab``), clicks
Run, and checks that the live plot image changes and that the results table
gains a row. A screenshot goes to ``tests/artifacts/``. Uses Debian's
``/usr/bin/chromium`` (Playwright never downloads a browser here); skipped when
it is missing. JupyterLab's autosave is switched off so the committed notebook
is never rewritten, and every kernel is shut down at the end.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request

import pytest

from course_helpers.core.waiting import poll_until

pytestmark = pytest.mark.browser

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NOTEBOOK = os.path.join(REPO, "notebooks", "08b_qos_lab.ipynb")
ARTIFACTS = os.path.join(REPO, "tests", "artifacts")
# Debian's chromium by default; COURSE_CHROMIUM may name another Chromium-based browser that is
# already installed (GitHub's Ubuntu runners have /usr/bin/google-chrome).
CHROMIUM = os.environ.get("COURSE_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = ["--no-sandbox", "--headless", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]
SETTINGS = {  # JupyterLab user settings for the test: no autosave, every cell in the DOM
    "@jupyterlab/docmanager-extension/plugin.jupyterlab-settings": {"autosave": False},
    "@jupyterlab/notebook-extension/tracker.jupyterlab-settings": {"windowingMode": "none"},
    "@jupyterlab/apputils-extension/notification.jupyterlab-settings": {"fetchNews": "false",
                                                                       "checkForUpdates": False},
}


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _api(base: str, token: str, path: str, method: str = "GET"):
    request = urllib.request.Request(f"{base}{path}", method=method,
                                     headers={"Authorization": f"token {token}"})
    with urllib.request.urlopen(request, timeout=10) as response:
        body = response.read()
    return json.loads(body) if body else None


@pytest.fixture
def jupyter_lab():
    """A JupyterLab server on a free port: yields (base_url, token); stops it and its kernels after."""
    if not os.path.exists(CHROMIUM):
        pytest.skip(f"{CHROMIUM} is missing: install Debian's chromium (apt-get install chromium) "
                    "or set COURSE_CHROMIUM to an installed Chromium-based browser to run the browser "
                    "tests; Playwright must not download a browser")
    pytest.importorskip("playwright.sync_api", reason="playwright (PyPI) is not installed")
    workdir = tempfile.mkdtemp(prefix="qos-lab-browser-")
    for name, values in SETTINGS.items():
        path = os.path.join(workdir, "settings", name)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, "w", encoding="utf-8") as handle:
            json.dump(values, handle)
    port, token = _free_port(), secrets.token_hex(16)
    env = dict(os.environ)
    env.pop("ROS_DOMAIN_ID", None)  # the kernel reserves its own domain
    env["JUPYTER_CONFIG_DIR"] = os.path.join(workdir, "config")
    log = open(os.path.join(workdir, "jupyter.log"), "wb")  # closed in the finally below
    server = subprocess.Popen(
        [sys.executable, "-m", "jupyter", "lab", "--no-browser", f"--port={port}",
         "--ServerApp.ip=127.0.0.1", f"--ServerApp.token={token}", "--notebook-dir=notebooks",
         f"--LabApp.user_settings_dir={os.path.join(workdir, 'settings')}",
         f"--LabApp.workspaces_dir={os.path.join(workdir, 'workspaces')}",
         f"--FileCheckpoints.root_dir={os.path.join(workdir, 'checkpoints')}",  # not in notebooks/
         "--LabApp.extension_manager=readonly", "--LabApp.news_url=None",
         "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate",
         *(["--allow-root"] if os.geteuid() == 0 else [])],
        cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    base = f"http://127.0.0.1:{port}"
    def answers() -> bool:
        try:
            _api(base, token, "/api/status")
            return True
        except OSError:
            return False

    try:
        if not poll_until(lambda: server.poll() is not None or answers(), 60, period=0.3) \
                or server.poll() is not None:
            log.flush()
            with open(log.name, "rb") as handle:
                pytest.fail(f"JupyterLab did not start:\n{handle.read()[-3000:].decode()}")
        yield base, token
    finally:
        try:
            for kernel in _api(base, token, "/api/kernels") or []:
                _api(base, token, f"/api/kernels/{kernel['id']}", method="DELETE")
            remaining = _api(base, token, "/api/kernels")
        except OSError:
            remaining = None
        try:
            os.killpg(server.pid, signal.SIGTERM)
            server.wait(timeout=15)
        except subprocess.TimeoutExpired:
            os.killpg(server.pid, signal.SIGKILL)
            server.wait(timeout=5)
        except ProcessLookupError:
            pass
        log.close()
        shutil.rmtree(workdir, ignore_errors=True)
        assert not remaining, f"kernels left running: {remaining}"


def test_lab_runs_in_a_real_browser(jupyter_lab):
    from playwright.sync_api import sync_playwright

    base, token = jupyter_lab
    before = hashlib.sha256(open(NOTEBOOK, "rb").read()).hexdigest()
    os.makedirs(ARTIFACTS, exist_ok=True)
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        page = browser.new_page(viewport={"width": 1400, "height": 1100})
        try:
            _run_the_lab(page, base, token)
        except Exception:
            page.screenshot(path=os.path.join(ARTIFACTS, "qos_lab_failure.png"))
            raise
        finally:
            browser.close()
    after = hashlib.sha256(open(NOTEBOOK, "rb").read()).hexdigest()
    assert before == after, "the browser session changed the committed notebook"


def _run_the_lab(page, base: str, token: str) -> None:
    page.goto(f"{base}/lab/tree/08b_qos_lab.ipynb?token={token}", timeout=60_000)
    page.wait_for_selector(".jp-Notebook .jp-Cell", timeout=60_000)
    # Wait until the kernel is up, then run the lab cell (tagged 'qos-lab'; found by its source).
    page.locator(".jp-StatusBar-Item", has_text="Idle").first.wait_for(timeout=90_000)
    cell = page.locator(".jp-CodeCell").filter(has_text="lab = qos_lab()").first
    cell.locator(".jp-InputArea-editor").click()
    page.keyboard.press("Shift+Enter")
    panel = page.locator(".qos-lab").first
    panel.wait_for(timeout=90_000)
    image = panel.locator("img").first
    image.wait_for(timeout=30_000)
    first_src = image.get_attribute("src")
    rows = panel.locator("table.qos-lab-results tbody tr td:nth-child(2)")  # a placeholder row has 1 cell
    rows_before = rows.count()
    panel.locator("button").filter(has_text=re.compile(r"^\s*Run\s*$")).click()
    sources, started = {first_src}, time.monotonic()
    poll_until(lambda: sources.add(image.get_attribute("src")) or rows.count() > rows_before, 60, period=0.05)
    _wait_until_finished(panel)
    _screenshot(panel, "qos_lab_panel.png")
    page.screenshot(path=os.path.join(ARTIFACTS, "qos_lab_page.png"))
    status = panel.locator(".qos-lab-status").inner_text()
    print(f"{len(sources) - 1} plot frames seen in the browser in {time.monotonic() - started:.1f} s; "
          f"status: {status}")
    assert rows.count() == rows_before + 1, status
    assert len(sources) >= 2, "the plot image did not change while the experiment ran"
    assert "Done" in status and "delivered" in status, status
    # One click loads a preset; Compare runs its two configurations and overlays them.
    panel.locator("button", has_text="depth 1 vs 100, slow subscriber").click()
    panel.locator("button").filter(has_text=re.compile(r"^\s*Compare\s*$")).click()
    sources, started = set(), time.monotonic()
    poll_until(lambda: sources.add(image.get_attribute("src")) or rows.count() >= rows_before + 3, 90,
               period=0.05)
    _wait_until_finished(panel)
    _screenshot(panel, "qos_lab_compare.png")
    status = panel.locator(".qos-lab-status").inner_text()
    print(f"compare: {len(sources)} plot frames in {time.monotonic() - started:.1f} s; status: {status}")
    assert rows.count() == rows_before + 3, status
    assert "Done" in status and "depth 1, 10 ms/sample: delivered" in status, status
    # A fast stream, set with the keyboard on the sliders: 2000 samples/s for 2 s, no processing time.
    panel.locator("button").filter(has_text=re.compile(r"^\s*best effort\s*$")).click()
    _slide(panel, "processing", 0, "0")
    _slide(panel, "rate", 11, "2000 Hz")  # the 12th rate
    _slide(panel, "duration", 38, "2.00")  # 0.1 s + 38 steps of 0.05 s
    # the kernel answers each slider change with a new status line: wait for it (a busy kernel is slow)
    panel.locator(".qos-lab-status", has_text="2000 Hz x 1 KiB").wait_for(timeout=30_000)
    # Time every new picture in the page itself, as the browser shows it.
    image.evaluate("img => { window.qosLabFrames = []; new MutationObserver(() => "
                   "window.qosLabFrames.push(performance.now())).observe(img, {attributes: true, "
                   "attributeFilter: ['src']}); }")
    panel.locator("button").filter(has_text=re.compile(r"^\s*Run\s*$")).click()
    poll_until(lambda: rows.count() >= rows_before + 4, 60, period=0.1)
    _wait_until_finished(panel)
    frames = page.evaluate("window.qosLabFrames")  # ms since page load
    status = panel.locator(".qos-lab-status").inner_text()
    span = (frames[-1] - frames[0]) / 1000 if len(frames) > 1 else 0.0
    print(f"fast stream: {len(frames)} frames in {span:.1f} s in the browser "
          f"({(len(frames) - 1) / span if span else 0:.1f} Hz); status: {status}")
    _screenshot(panel, "qos_lab_fast.png")
    assert rows.count() == rows_before + 4, status
    # How many live frames the kernel draws depends on the CPU it gets (this machine is shared): at
    # least one besides the final picture shows that the plot follows a fast stream.
    assert len(frames) >= 2, "the plot did not follow a fast stream"
    assert "Traceback" not in page.content()


def _screenshot(panel, name: str) -> None:
    """Save the panel's picture; a widget that re-renders meanwhile detaches the element, and is then
    found again (the picture is for readers of tests/artifacts, not a check)."""
    for attempt in range(3):
        try:
            panel.screenshot(path=os.path.join(ARTIFACTS, name), timeout=30_000)
            return
        except Exception as error:  # playwright's Error: "Element is not attached to the DOM"
            if "not attached" not in str(error) or attempt == 2:
                raise


def _wait_until_finished(panel) -> None:
    """Wait for the panel's last status ('Done' or 'Stopped'), which it shows after the final picture."""
    last = re.compile(r"^\s*(Done|Stopped|The experiment failed)")
    panel.locator(".qos-lab-status").filter(has_text=last).first.wait_for(timeout=60_000)


def _slide(panel, description: str, steps: int, shows: str) -> None:
    """Move a slider of the panel to its first value, then ``steps`` steps up, with the keyboard, until
    its readout ``shows`` the value (a busy kernel's echo of an earlier value can swallow a key press:
    then the keys are pressed again)."""
    slider = panel.locator(".widget-slider", has_text=description)
    handle, readout = slider.locator(".noUi-handle"), slider.locator(".widget-readout")
    for _attempt in range(3):
        handle.press("Home")
        for _ in range(steps):
            handle.press("ArrowRight")
        if poll_until(lambda: readout.inner_text().strip() == shows, 5.0, period=0.1):
            return
    raise AssertionError(f"the {description} slider shows {readout.inner_text()!r}, not {shows!r}")
