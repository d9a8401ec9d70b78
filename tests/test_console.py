"""Node consoles without a kernel: which lines a console keeps, and what nbval compares of it.

``test_kernel.py`` shows the consoles in a real kernel, cell by cell.
"""

from __future__ import annotations

import os
import re

from nbval.plugin import get_sanitize_patterns

from course_helpers.core.console import Cell, ConsoleRouter, NodeConsole

from .conftest import REPO


def sanitized(text: str) -> str:
    """``text`` after the replacements strict nbval applies before comparing (tests/nbval_sanitize.cfg)."""
    with open(os.path.join(REPO, "tests", "nbval_sanitize.cfg"), encoding="utf-8") as handle:
        for regex, replace in get_sanitize_patterns(handle.read()):
            text = re.sub(regex, replace, text)
    return text


def test_a_console_looks_the_same_to_nbval_under_every_cell():
    """Whatever lines a console shows under a cell, nbval compares it as its empty form."""
    console = NodeConsole("/ns/talker")
    empty = {kind: sanitized(text) for kind, text in console.empty_bundle().items()}
    for text in ("[INFO] [1795690421.650] [talker]: hello", "one\ntwo\n<b>three</b> & 'four'"):
        shown = console.bundle(text)
        assert "hello" in shown["text/plain"] or "three" in shown["text/plain"]
        assert {kind: sanitized(value) for kind, value in shown.items()} == empty, shown
    assert console.bundle("") == console.empty_bundle()  # a part without lines shows nothing


def test_log_lines_of_a_node_without_a_console_yet_go_into_its_console():
    """A constructor's log line may come through /rosout before rt.add gives the node a console."""
    router = ConsoleRouter()
    assert router.write_log("greeter", "[INFO] up and ready") is False
    assert router.write_log("someone_else", "[INFO] not mine") is False
    console = router.open("greeter", "/greeter", show=False)
    assert console.text() == "[INFO] up and ready"
    router._cell_starts()  # a new cell: older lines without a console belong to no cell now
    router.write_log("late", "[INFO] from before")
    router._cell_starts()
    assert router.open("late", "/late", show=False).text() == ""


def test_a_log_line_does_not_split_a_printed_line():
    console = NodeConsole("/printer", show=False)
    console.write("half a line")
    console.write_line("[INFO] a log line")
    console.write(", then the rest\n")
    assert console.text() == "[INFO] a log line\nhalf a line, then the rest"


def test_lines_of_another_cell_start_another_part():
    cells = [Cell({"msg_id": "a"})]
    console = NodeConsole("/node", show=True, cell_now=lambda: cells[-1])
    console.write("in cell a\n")
    first = console.display_id
    cells.append(Cell({"msg_id": "b"}))
    console.write("in cell b\n")
    assert console.display_id != first
    assert console.text() == "in cell a\nin cell b"  # the node's recent lines, across its parts
