"""The committed chapters' reading paths (tools/reading_path.py): core paths within their budget, and
deep dives that say what they are, in the notebook and on the static page alike."""

from __future__ import annotations

import glob
import json
import os

import pytest

from tools.reading_path import DEEP_DIVE, HEADING, chapter, heading_level

from .conftest import REPO

NOTEBOOKS = sorted(glob.glob(os.path.join(REPO, "notebooks", "*.ipynb")))
CORE_WORDS = {  # issue 32: a core path a student reads in about an hour, the rest in deep dives
    "07_dds_and_discovery": 3000,
}
DEEP_DIVE_TITLE = "Deep dive (optional):"


@pytest.mark.parametrize("name, most", sorted(CORE_WORDS.items()))
def test_the_core_path_keeps_to_its_words(name, most):
    found = chapter(os.path.join(REPO, "notebooks", f"{name}.ipynb"))
    assert found.core.words <= most, (f"{name}: {found.core.words} words of prose on the core path, at most "
                                      f"{most}: tighten it, or move what the objectives do not need into a "
                                      "deep dive")


def deep_dive_problems(cells: list[dict]) -> list[str]:
    """What is wrong with the deep-dive headings of a notebook's cells: each is collapsed in JupyterLab
    and its title starts with 'Deep dive (optional):', so a reader of the static page knows too."""
    found = []
    for index, cell in enumerate(cells):
        if DEEP_DIVE not in cell.get("metadata", {}).get("tags", []) or heading_level(cell) is None:
            continue
        title = HEADING.sub("", "".join(cell["source"]).lstrip().splitlines()[0]).strip()
        if not title.startswith(DEEP_DIVE_TITLE):
            found.append(f"cell {index}: the heading {title!r} does not start with {DEEP_DIVE_TITLE!r}")
        if cell["metadata"].get("jp-MarkdownHeadingCollapsed") is not True:
            found.append(f"cell {index}: the deep dive {title!r} is not collapsed "
                         "(metadata jp-MarkdownHeadingCollapsed)")
    return found


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[os.path.basename(p) for p in NOTEBOOKS])
def test_every_deep_dive_is_collapsed_and_says_so(path):
    with open(path, encoding="utf-8") as handle:
        cells = json.load(handle)["cells"]
    assert not deep_dive_problems(cells)


def test_the_deep_dive_check_finds_a_plain_title_and_an_open_section():
    def heading(text, collapsed):
        metadata = {"tags": [DEEP_DIVE]} | ({"jp-MarkdownHeadingCollapsed": True} if collapsed else {})
        return {"cell_type": "markdown", "metadata": metadata, "source": [text]}

    assert not deep_dive_problems([heading("### Deep dive (optional): ports\ntext", True)])
    assert len(deep_dive_problems([heading("### Ports\ntext", True)])) == 1
    assert len(deep_dive_problems([heading("### Deep dive (optional): ports", False)])) == 1
