"""The course website (``make book``) in a real browser: every chapter, its images and its links.

Builds the site from the committed notebooks, serves it from a local HTTP server, and visits the
landing page and every chapter in headless Debian Chromium driven by Playwright. Each page must
have its title, every image must have loaded (natural width > 0), every internal link must
answer, and each chapter's quiz must show its answers under "Questions and answers".
Screenshots of the landing page, 08b and 10 go to ``tests/artifacts/``. Skipped when Chromium is
missing (Playwright never downloads a browser here).
"""

from __future__ import annotations

import glob
import http.server
import json
import os
import subprocess
import sys
import threading
import urllib.error
import urllib.parse
import urllib.request
from functools import partial

import pytest

from course_helpers.notebook.quiz import Quiz

from .browsers import artifact, browser_page, require_chromium
from .conftest import REPO

pytestmark = [pytest.mark.browser, pytest.mark.slow, pytest.mark.xdist_group("book")]

SITE = os.path.join(REPO, "build", "book", "html")
CHAPTERS = sorted(os.path.splitext(os.path.basename(p))[0]
                  for p in glob.glob(os.path.join(REPO, "notebooks", "*.ipynb")))
SCREENSHOTS = {"index": "book_landing.png", "08b_qos_lab": "book_08b_qos_lab.png",
               "10_capstone": "book_10_capstone.png"}


def _title_of(chapter: str) -> str:
    with open(os.path.join(REPO, "notebooks", f"{chapter}.ipynb"), encoding="utf-8") as handle:
        cells = json.load(handle)["cells"]
    heading = "".join(next(c for c in cells if c["cell_type"] == "markdown")["source"]).splitlines()[0]
    return heading.lstrip("# ").strip()


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *_args):
        pass


@pytest.fixture(scope="module")
def site():
    """The freshly built site served on a free localhost port: yields its base URL."""
    require_chromium()
    build = subprocess.run([sys.executable, os.path.join(REPO, "tools", "build_book.py")], cwd=REPO,
                           capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stdout + build.stderr
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), partial(_QuietHandler, directory=SITE))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()


def _answers(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=10) as response:
            return response.status == 200
    except urllib.error.URLError:
        return False


def test_every_chapter_page_has_its_title_images_and_working_links(site):
    """One test for the whole site, so it is built once (two workers would rebuild it under each other)."""
    _site_shows_static_records_not_widget_reprs()
    problems, checked_links = [], set()
    with browser_page(1280, 900) as page:
        for name in ["index", *CHAPTERS]:
            url = f"{site}/{name}.html"
            response = page.goto(url, wait_until="load")
            if response is None or response.status != 200:
                problems.append(f"{name}: HTTP {response and response.status}")
                continue
            heading = page.locator("main h1").first.inner_text().replace("#", "").strip()
            expected = "ROS 2 architecture, live" if name == "index" else _title_of(name)
            if heading != expected:
                problems.append(f"{name}: title {heading!r}, expected {expected!r}")
            images = page.eval_on_selector_all(
                "main img", "imgs => imgs.map(i => [i.currentSrc.slice(0, 60), i.naturalWidth])")
            problems += [f"{name}: image {src!r} did not load" for src, width in images if width == 0]
            if name != "index" and not images:
                problems.append(f"{name}: no images at all")
            links = page.eval_on_selector_all("a[href]", "links => links.map(a => a.href)")
            for link in links:
                target = urllib.parse.urldefrag(link).url
                if target.startswith(site) and target not in checked_links:
                    checked_links.add(target)
                    if not _answers(target):
                        problems.append(f"{name}: broken link {target}")
            if name != "index":
                problems += _quiz_answers_shown(page, name)
            if name in SCREENSHOTS:
                page.screenshot(path=artifact(SCREENSHOTS[name]), full_page=False)
    assert not problems, "\n".join(problems)
    assert len(checked_links) > len(CHAPTERS)  # the navigation links every chapter


def _quiz_answers_shown(page, name: str) -> list[str]:
    """The chapter's quiz on its page: "Questions and answers" opens on every question with its right
    answers marked (the notebook itself shows none; tools/build_book.py puts them in)."""
    quiz = Quiz.load(name)
    details = page.locator("main details", has=page.locator("summary", has_text="Questions and answers"))
    if details.count() != 1:
        return [f"{name}: {details.count()} 'Questions and answers' sections, expected one"]
    details.locator("summary").click()
    shown = details.inner_text()
    right = [c.text for q in quiz.questions for c in q.choices if c.correct]
    problems = [f"{name}: the answer {text!r} is not marked right" for text in right
                if f"\u2714 {text}" not in shown]
    if shown.count("\u2714") != len(right):
        problems.append(f"{name}: {shown.count(chr(0x2714))} answers marked right, expected {len(right)}")
    return problems


def _site_shows_static_records_not_widget_reprs():
    for name in CHAPTERS:
        with open(os.path.join(SITE, f"{name}.html"), encoding="utf-8") as handle:
            text = handle.read()
        for bare in ("HBox(children", "VBox(children", "[console of", "FloatProgress(value"):
            assert bare not in text, f"{name}.html shows a widget's bare repr {bare!r}"
