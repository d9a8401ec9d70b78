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
import os
import re
import time

import pytest

from course_helpers.core.waiting import poll_until

from .browsers import HANG_MS, artifact, browser_page, require_chromium
from .lab_page import screenshot_widget, wait_until_lab_finished
from .servers import jupyter_lab

pytestmark = pytest.mark.browser

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NOTEBOOK = os.path.join(REPO, "notebooks", "08b_qos_lab.ipynb")


def test_lab_runs_in_a_real_browser():
    require_chromium()
    before = hashlib.sha256(open(NOTEBOOK, "rb").read()).hexdigest()
    with jupyter_lab() as lab, browser_page(on_failure="qos_lab_failure.png") as page:
        _run_the_lab(page, lab.base, lab.token)
    after = hashlib.sha256(open(NOTEBOOK, "rb").read()).hexdigest()
    assert before == after, "the browser session changed the committed notebook"


def _run_the_lab(page, base: str, token: str) -> None:
    page.goto(f"{base}/lab/tree/08b_qos_lab.ipynb?token={token}", timeout=HANG_MS)
    page.wait_for_selector(".jp-Notebook .jp-Cell", timeout=HANG_MS)
    # Wait until the kernel is up, then run the lab cell (tagged 'qos-lab'; found by its source).
    page.locator(".jp-StatusBar-Item", has_text="Idle").first.wait_for(timeout=HANG_MS)
    cell = page.locator(".jp-CodeCell").filter(has_text="lab = qos_lab()").first
    cell.locator(".jp-InputArea-editor").click()
    page.keyboard.press("Shift+Enter")
    panel = page.locator(".qos-lab").first
    panel.wait_for(timeout=HANG_MS)
    image = panel.locator("img").first
    image.wait_for(timeout=HANG_MS)
    first_src = image.get_attribute("src")
    rows = panel.locator("table.qos-lab-results tbody tr td:nth-child(2)")  # a placeholder row has 1 cell
    rows_before = rows.count()
    panel.locator("button").filter(has_text=re.compile(r"^\s*Run\s*$")).click()
    sources, started = {first_src}, time.monotonic()
    poll_until(lambda: sources.add(image.get_attribute("src")) or rows.count() > rows_before, 60, period=0.05)
    wait_until_lab_finished(panel)
    screenshot_widget(panel, "qos_lab_panel.png")
    page.screenshot(path=artifact("qos_lab_page.png"))
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
    wait_until_lab_finished(panel)
    screenshot_widget(panel, "qos_lab_compare.png")
    status = panel.locator(".qos-lab-status").inner_text()
    print(f"compare: {len(sources)} plot frames in {time.monotonic() - started:.1f} s; status: {status}")
    assert rows.count() == rows_before + 3, status
    assert "Done" in status and "depth 1, 10 ms/sample: delivered" in status, status
    # A fast stream, set with the keyboard on the sliders: 2000 samples/s for 2 s, no processing time.
    panel.locator("button").filter(has_text=re.compile(r"^\s*best effort\s*$")).click()
    _slide(panel, "processing", 0, "0")
    _slide(panel, "rate", 11, "2000 Hz")  # the 12th rate
    _slide(panel, "duration", 38, "2.00")  # 0.1 s + 38 steps of 0.05 s
    # The kernel answers each slider change with a new status line, for certain once the run has ended;
    # a busy kernel answers late, so the bound only ends a hang.
    panel.locator(".qos-lab-status", has_text="2000 Hz x 1 KiB").wait_for(timeout=HANG_MS)
    # Time every new picture in the page itself, as the browser shows it.
    image.evaluate("img => { window.qosLabFrames = []; new MutationObserver(() => "
                   "window.qosLabFrames.push(performance.now())).observe(img, {attributes: true, "
                   "attributeFilter: ['src']}); }")
    panel.locator("button").filter(has_text=re.compile(r"^\s*Run\s*$")).click()
    poll_until(lambda: rows.count() >= rows_before + 4, 60, period=0.1)
    wait_until_lab_finished(panel)
    frames = page.evaluate("window.qosLabFrames")  # ms since page load
    status = panel.locator(".qos-lab-status").inner_text()
    span = (frames[-1] - frames[0]) / 1000 if len(frames) > 1 else 0.0
    print(f"fast stream: {len(frames)} frames in {span:.1f} s in the browser "
          f"({(len(frames) - 1) / span if span else 0:.1f} Hz); status: {status}")
    screenshot_widget(panel, "qos_lab_fast.png")
    assert rows.count() == rows_before + 4, status
    # How many live frames the kernel draws depends on the CPU it gets (this machine is shared): at
    # least one besides the final picture shows that the plot follows a fast stream.
    assert len(frames) >= 2, "the plot did not follow a fast stream"
    assert "Traceback" not in page.content()


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
