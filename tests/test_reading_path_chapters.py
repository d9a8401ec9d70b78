"""The committed chapters' reading paths (tools/reading_path.py): core paths within their budget, and
deep dives that say what they are, in the notebook and on the static page alike."""

from __future__ import annotations

import ast
import glob
import os

import pytest
from IPython.core.inputtransformer2 import TransformerManager

from tools.reading_path import DEEP_DIVE, HEADING, chapter, heading_level, notebook_cells, walk

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
    assert not deep_dive_problems(notebook_cells(path))


def test_the_deep_dive_check_finds_a_plain_title_and_an_open_section():
    def heading(text, collapsed):
        metadata = {"tags": [DEEP_DIVE]} | ({"jp-MarkdownHeadingCollapsed": True} if collapsed else {})
        return {"cell_type": "markdown", "metadata": metadata, "source": [text]}

    assert not deep_dive_problems([heading("### Deep dive (optional): ports\ntext", True)])
    assert len(deep_dive_problems([heading("### Ports\ntext", True)])) == 1
    assert len(deep_dive_problems([heading("### Deep dive (optional): ports", False)])) == 1


def _bound_and_used(code: str) -> tuple[set[str], set[str]]:
    """Names a code cell binds (assignments, imports, defs) and names it reads (magics as IPython runs
    them)."""
    tree = ast.parse(TransformerManager().transform_cell(code))
    bound, used = set(), set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            (used if isinstance(node.ctx, ast.Load) else bound).add(node.id)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            bound.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            bound.update((alias.asname or alias.name).split(".")[0] for alias in node.names)
    return bound, used


def core_needs_a_deep_dive(cells: list[dict]) -> list[str]:
    """Names a core code cell reads that only a deep dive before it binds: a student who skips the
    collapsed sections would meet a NameError there."""
    found, core_bound, deep_bound = [], set(), set()
    for index, (cell, in_deep_dive) in enumerate(walk(cells)):
        if cell["cell_type"] != "code":
            continue
        bound, used = _bound_and_used("".join(cell["source"]))
        if in_deep_dive:
            deep_bound |= bound
            continue
        for name in sorted((used & deep_bound) - core_bound - bound):
            found.append(f"cell {index} reads {name!r}, which only a deep dive binds")
        core_bound |= bound
    return found


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[os.path.basename(p) for p in NOTEBOOKS])
def test_the_core_path_needs_no_deep_dive(path):
    assert not core_needs_a_deep_dive(notebook_cells(path))


def test_the_check_finds_a_core_cell_that_reads_a_deep_dives_name():
    def cell(kind, text, tags=()):
        return {"cell_type": kind, "metadata": {"tags": list(tags)}, "source": [text]}

    cells = [cell("markdown", "## Deep dive (optional): x", [DEEP_DIVE]), cell("code", "traffic = measure()"),
             cell("markdown", "## Back"), cell("code", "%ros2 node list\nprint(traffic)")]
    assert core_needs_a_deep_dive(cells) == ["cell 3 reads 'traffic', which only a deep dive binds"]
    cells.insert(3, cell("code", "traffic = measure()"))
    assert not core_needs_a_deep_dive(cells)
