"""What every browser test needs before and around its page: Debian's Chromium driven by Playwright.

* :func:`require_chromium` skips the test, with the reason, where Chromium or Playwright is missing
  (Playwright never downloads a browser here; ``COURSE_CHROMIUM`` may name another installed
  Chromium-based browser, e.g. GitHub's ``/usr/bin/google-chrome``);
* :func:`browser_page` opens one page in headless Chromium, saves a screenshot to ``tests/artifacts/``
  when the block fails, and closes the browser;
* :func:`artifact` is the path of a file in ``tests/artifacts/`` (git-ignored), made on demand;
* :data:`HANG_MS`: the bound on every wait for what the page does for certain, which only ends a hang;
* :data:`LAB_SETTINGS` and :func:`write_lab_settings`: JupyterLab's user settings for a test (no
  autosave, so a committed notebook is never rewritten; every cell in the page; no news).

How a student's clicks and keys drive JupyterLab's page is in ``tests/lab_page.py``.
"""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
ARTIFACTS = REPO / "tests" / "artifacts"
CHROMIUM = os.environ.get("COURSE_CHROMIUM", "/usr/bin/chromium")
# ms; the one bound on a browser test's wait for what the page does for certain (a page loads, a kernel
# starts, a cell's output or a lab run arrives, an element is drawn): it ends a hang and judges nothing
HANG_MS = 240_000
# s; the bound on a whole browser test that sets none of its own (tests/conftest.py adds it): pytest's
# default of 120 s is shorter than one of the test's own waits, so on a busy machine (the logic stage's
# five workers on two cores) it cut short a QoS lab run that was still progressing, before the test's
# own wait could say what, if anything, hung. Like HANG_MS it ends a hang and judges nothing.
TEST_HANG_S = 3 * HANG_MS // 1000
CHROMIUM_ARGS = ["--no-sandbox", "--headless", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]
LAB_SETTINGS = {  # JupyterLab user settings for the tests: no autosave, every cell in the DOM, no news
    "@jupyterlab/docmanager-extension/plugin.jupyterlab-settings": {"autosave": False},
    "@jupyterlab/notebook-extension/tracker.jupyterlab-settings": {"windowingMode": "none"},
    "@jupyterlab/apputils-extension/notification.jupyterlab-settings": {"fetchNews": "false",
                                                                       "checkForUpdates": False},
}


def require_chromium() -> None:
    """Skip the calling test, saying what to install, unless Chromium and Playwright are both here."""
    if not os.path.exists(CHROMIUM):
        pytest.skip(f"{CHROMIUM} is missing: install Debian's chromium (apt-get install chromium) or set "
                    "COURSE_CHROMIUM to an installed Chromium-based browser to run the browser tests; "
                    "Playwright must not download a browser")
    pytest.importorskip("playwright.sync_api", reason="playwright (PyPI) is not installed")


def artifact(name: str) -> str:
    """The path of ``tests/artifacts/<name>`` (the folder is made if needed)."""
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    return str(ARTIFACTS / name)


@contextlib.contextmanager
def browser_page(width: int = 1400, height: int = 1100, on_failure: str | None = None) -> Iterator:
    """A page of headless Chromium (a Playwright ``Page``) for the block. If the block raises, the page
    is saved first as ``tests/artifacts/<on_failure>``. The browser is closed afterwards."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        try:
            page = browser.new_page(viewport={"width": width, "height": height})
            try:
                yield page
            except Exception:
                if on_failure:
                    with contextlib.suppress(Exception):  # the failure, not the screenshot, is the news
                        page.screenshot(path=artifact(on_failure))
                raise
        finally:
            browser.close()


def write_lab_settings(folder: str | Path) -> Path:
    """Write :data:`LAB_SETTINGS` as JupyterLab's user-settings folder ``folder``; returns it."""
    folder = Path(folder)
    for name, values in LAB_SETTINGS.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(values), encoding="utf-8")
    return folder
