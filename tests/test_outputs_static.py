"""Every committed output means something without a kernel (GitHub, nbviewer, the course website).

A widget's saved output is shown by renderers without widget support through its other forms
only. Those must be a real record (text, HTML or a picture), never a bare repr such as
``HBox(children=(...))``, ``[console of /talker]`` or ``<colcon build progress>``, and a node
console is never an empty placeholder.
"""

from __future__ import annotations

import glob
import json
import os
import re

import pytest

from .conftest import REPO

NOTEBOOKS = sorted(glob.glob(os.path.join(REPO, "notebooks", "*.ipynb")))
WIDGET = "application/vnd.jupyter.widget-view+json"
# What Python prints for an object that has nothing better to say: Name(...) or <...>.
BARE_REPR = re.compile(r"^\s*([A-Z]\w*\((children|value|layout|period_s|description)=.*|<[^\n<>]*>)\s*$",
                       re.S)
PLACEHOLDERS = re.compile(r"\[console of |^console of \S+:\s*$")


def _text(value) -> str:
    return "".join(value) if isinstance(value, list) else str(value)


def problems_of(output: dict) -> list[str]:
    """What a reader without a kernel would see wrong in one saved output."""
    data = output.get("data", {})
    plain = _text(data.get("text/plain", ""))
    found = []
    if PLACEHOLDERS.search(plain):
        found.append(f"a console placeholder with no lines: {plain[:60]!r}")
    if WIDGET in data:
        static = {k for k in data if k not in (WIDGET, "text/plain")}
        if not static and (not plain.strip() or BARE_REPR.match(plain)):
            found.append(f"a widget whose only other form is {plain[:70]!r}")
    elif not (set(data) - {"text/plain"}) and BARE_REPR.match(plain) and "Figure" not in plain:
        # a figure's repr comes with its PNG in the same cell; other bare reprs are noise
        if re.match(r"^\s*(HBox|VBox|Output|FloatProgress|IntProgress|Button|LiveGraphView)\(", plain):
            found.append(f"a widget saved without its view: {plain[:70]!r}")
    return found


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[os.path.basename(p) for p in NOTEBOOKS])
def test_every_output_means_something_without_a_kernel(path):
    with open(path, encoding="utf-8") as handle:
        cells = json.load(handle)["cells"]
    found = [f"cell {index}: {problem}"
             for index, cell in enumerate(cells) if cell["cell_type"] == "code"
             for output in cell.get("outputs", []) for problem in problems_of(output)]
    assert not found, (f"{os.path.basename(path)}: outputs that say nothing without a kernel:\n"
                       + "\n".join(found))


@pytest.mark.parametrize("output, bad", [
    ({"data": {WIDGET: {}, "text/plain": "HBox(children=(FloatProgress(value=0.0, max=6.0),))"}}, True),
    ({"data": {WIDGET: {}, "text/plain": "<colcon build progress>"}}, True),
    ({"data": {WIDGET: {}, "text/plain": "[console of /talker]"}}, True),
    ({"data": {"text/plain": "console of /talker:\n"}}, True),
    ({"data": {WIDGET: {}, "text/plain": "[record] lab\n2 runs", "text/html": "<table></table>"}}, False),
    ({"data": {"text/plain": "console of /talker:\n[INFO] hi", "text/html": "<pre>hi</pre>"}}, False),
    ({"data": {"text/plain": "", "text/html": "<div class='course-console'></div>"}}, False),
])
def test_the_check_tells_a_record_from_a_bare_repr(output, bad):
    assert bool(problems_of(output)) is bad
