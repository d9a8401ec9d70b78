"""The QoS lab says what goes on around a run (issue 31, item 3).

* During a run, its progress line is rewritten while the run goes: the seconds so far, first while the
  publisher's process starts, then the samples sent and delivered so far.
* Before a run, with another course kernel running (a real Jupyter kernel with a course runtime), the
  panel says so, naming it and what it costs, before the run's first progress line.

Every change of the panel's lines is recorded as it happens (a traitlets observer on each widget).
"""

from __future__ import annotations

import html
import os
import re
import time

import pytest

from course_helpers.chapters.ch08b_lab import ExperimentConfig, qos_lab
from tests.kernel_session import KernelSession

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SO_FAR = re.compile(r"Run 1/1 \(.*\): (\d+\.\d) s so far(, starting the publisher's process|; (\d+) sent "
                    r"and (\d+) delivered)")


def _recorded(lab) -> list[tuple[float, str, str]]:
    """(when, which line, its text) for every change of the progress and busy lines, from now on."""
    seen: list[tuple[float, str, str]] = []
    for name, widget in (("progress", lab.feedback.progress), ("busy", lab.feedback.busy_text)):
        widget.observe(lambda change, name=name: seen.append(
            (time.monotonic(), name, html.unescape(re.sub(r"<[^>]+>", "", change["new"])))), names="value")
    return seen


@pytest.mark.timing
def test_the_progress_line_counts_while_a_run_goes(rt):
    lab = qos_lab()
    try:
        seen = _recorded(lab)
        lab.start([ExperimentConfig(reliability="reliable", rate_hz=200, duration_s=2.0)])
        assert lab.wait(120), "the run did not end"
        lines = [text for _when, name, text in seen if name == "progress"]
        counting = [SO_FAR.search(line) for line in lines]
        counting = [found for found in counting if found]
        print(f"{len(counting)} progress lines, e.g. {lines[:2]} ... {lines[-2:]}")
        elapsed = [float(found.group(1)) for found in counting]
        assert len(counting) >= 4, lines  # a 2 s run is rewritten every 0.5 s at least four times
        assert elapsed == sorted(elapsed) and elapsed[-1] > elapsed[0], elapsed
        assert counting[0].group(2).startswith(", starting"), lines  # before anything is sent
        sent = [(int(f.group(3)), int(f.group(4))) for f in counting if f.group(3)]
        assert sent and sent[-1][0] > 0 and all(d <= s for s, d in sent), sent  # never more delivered
        assert lines[-1].startswith("Run 1/1") and "s in all" in lines[-1], lines[-1]
        assert lab.results[0].published == 400
    finally:
        lab.close()


def test_the_panel_says_the_machine_is_busy_before_the_run_when_another_course_kernel_runs(rt):
    other = KernelSession(cwd=os.path.join(REPO, "notebooks"),
                          env={"JPY_SESSION_NAME": os.path.join(REPO, "notebooks", "03_topics.ipynb")})
    lab = qos_lab()
    try:
        out, error = other.run("from course_helpers import get_runtime\nrt = get_runtime()\nprint('ok')")
        assert error is None and "ok" in out, out
        seen = _recorded(lab)
        lab.start([ExperimentConfig(reliability="best_effort", rate_hz=100, duration_s=0.5)])
        assert lab.wait(120), "the run did not end"
        busy = [(when, text) for when, name, text in seen if name == "busy" and text]
        first_run_line = min(when for when, name, text in seen if name == "progress" and "Run 1/1" in text)
        print(busy[0][1] if busy else seen)
        assert busy, f"the panel said nothing about the other kernel: {seen}"
        when, text = busy[0]
        assert when < first_run_line, "the warning came after the run had started"
        assert text.startswith("Before this run, this machine is "), text
        assert f"03_topics.ipynb (pid {other.process.pid} in domain" in text, text
        # the count and its verb agree ("1 other course kernel is running"), whatever else runs here
        count = re.search(r"; (\d+) other course kernels?( and \d+ child process(es)? of other course "
                          r"kernels)? (is|are) running", text)
        assert count, text
        one = count.group(1) == "1" and not count.group(2)
        assert count.group(4) == ("is" if one else "are"), text
        assert "What it costs:" in text and "rt.shutdown_other_kernels()" in text, text
        assert lab.feedback.busy_box.layout.display != "none"
        assert lab.feedback.shutdown_button.layout.display != "none"  # the notice's action
    finally:
        lab.close()
        other.shutdown()
