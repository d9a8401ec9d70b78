"""Committed outputs that strict nbval compares must not depend on the interpreter or the host.

Every supported Python (3.10-3.13) and every machine must reproduce them, after the replacements
in ``tests/nbval_sanitize.cfg``. This test looks for what would differ: the interpreter's version,
the Linux kernel's release, the host name, and the paths of this checkout, its venv and the home
folder, in every text representation (``text/plain``, ``text/html``, streams, errors).
"""

from __future__ import annotations

import configparser
import glob
import json
import os
import platform
import re
import socket
import sys

import pytest

from .conftest import REPO

NOTEBOOKS = sorted(glob.glob(os.path.join(REPO, "notebooks", "*.ipynb")))
IGNORE_MARKERS = ("NBVAL_IGNORE_OUTPUT", "NBVAL_SKIP")
PYTHON_MENTION = re.compile(r"(?i)\bpython ?3\.\d+|\bpy3\.\d+|\bcp3\d{1,2}\b|\bthis is 3\.\d+")


def _sanitizers() -> list[tuple[re.Pattern, str]]:
    parser = configparser.ConfigParser(interpolation=None)
    parser.read(os.path.join(REPO, "tests", "nbval_sanitize.cfg"))
    return [(re.compile(parser[s]["regex"]), parser[s]["replace"]) for s in parser.sections()]


def _host_values() -> dict[str, str]:
    values = {
        "the interpreter's full version": platform.python_version(),
        "this checkout's path": REPO,
        "the venv's path": sys.prefix,
        "the home folder": os.path.expanduser("~"),
        "the host name": socket.gethostname(),
        "the Linux kernel release": platform.release(),
    }
    return {what: value for what, value in values.items() if len(value) >= 4}


def _compared_texts(cell) -> list[str]:
    """The texts of a code cell's outputs that nbval compares (none if the cell is ignored)."""
    if cell.get("cell_type") != "code" or any(m in "".join(cell.get("source", "")) for m in IGNORE_MARKERS):
        return []
    texts = []
    for output in cell.get("outputs", []):
        if "text" in output:
            texts.append("".join(output["text"]))
        for mime, value in output.get("data", {}).items():
            if mime.startswith("text/"):
                texts.append("".join(value) if isinstance(value, list) else str(value))
        if output.get("output_type") == "error":
            texts.append("\n".join(output.get("traceback", [])))
    return texts


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[os.path.basename(p) for p in NOTEBOOKS])
def test_compared_outputs_hold_nothing_host_specific(path):
    with open(path, encoding="utf-8") as handle:
        notebook = json.load(handle)
    sanitizers = _sanitizers()
    found = []
    for index, cell in enumerate(notebook["cells"]):
        for text in _compared_texts(cell):
            for pattern, replacement in sanitizers:
                text = pattern.sub(replacement, text)
            for what, value in _host_values().items():
                if value in text:
                    found.append(f"cell {index}: {what} ({value!r})")
            found += [f"cell {index}: a Python version ({match.group(0)!r})"
                      for match in PYTHON_MENTION.finditer(text)]
    assert not found, (f"{os.path.basename(path)} has outputs that differ on another Python or machine; "
                       "print something stable, or mark the cell NBVAL_IGNORE_OUTPUT with an assert:\n"
                       + "\n".join(found))


def test_the_check_sees_a_python_version_in_html():
    cell = {"cell_type": "code", "source": "check()", "outputs": [
        {"output_type": "execute_result", "data": {"text/html": "<li>Python 3.10-3.13 (this is 3.12)</li>"}}]}
    texts = _compared_texts(cell)
    assert texts and PYTHON_MENTION.search(texts[0])
