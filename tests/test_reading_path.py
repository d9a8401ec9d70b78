"""tools/reading_path.py: what counts as a chapter's core path, and the committed chapters' figures."""

from __future__ import annotations

import json

from tools.reading_path import DEEP_DIVE, chapter, prose_words


def _markdown(text: str, tags=()) -> dict:
    return {"cell_type": "markdown", "metadata": {"tags": list(tags)}, "source": [text]}


def _code(seconds=None) -> dict:
    metadata = {} if seconds is None else {"course_run_s": seconds}
    return {"cell_type": "code", "metadata": metadata, "source": ["x = 1"], "outputs": []}


def test_a_deep_dive_runs_to_the_next_heading_of_its_level(tmp_path):
    cells = [_markdown("# Title\none two"), _code(1.0),
             _markdown("## Deep\nthree four five", tags=[DEEP_DIVE]), _code(10.0),
             _markdown("### inside\nsix"), _code(),
             _markdown("## Back\nseven eight"), _code(2.0),
             _markdown("a lone aside", tags=[DEEP_DIVE])]
    path = tmp_path / "nb.ipynb"
    path.write_text(json.dumps({"cells": cells, "metadata": {}, "nbformat": 4, "nbformat_minor": 5}))
    found = chapter(str(path))
    assert (found.core.words, found.core.run_s) == (3 + 3, 3.0)  # a heading's words count
    assert (found.deep.words, found.deep.run_s, found.deep.unmeasured) == (4 + 2 + 3, 10.0, 1)


def test_code_blocks_in_prose_are_not_words():
    assert prose_words("Run this:\n```python\nrt = get_runtime()\n```\nthen look.") == 4


def test_a_heading_inside_a_cell_ends_a_deep_dive_as_jupyterlab_does(tmp_path):
    """JupyterLab collapses by cells: a cell whose highest heading is of the deep dive's level or higher
    ends it, wherever in the cell that heading stands, and the whole cell is on the core path."""
    cells = [_markdown("## Deep\none two", tags=[DEEP_DIVE]), _code(5.0),
             _markdown("three four\n\n## Next section\nfive"), _code(1.0),
             _markdown("```bash\n# not a heading\n```\nsix")]
    path = tmp_path / "nb.ipynb"
    path.write_text(json.dumps({"cells": cells, "metadata": {}, "nbformat": 4, "nbformat_minor": 5}))
    found = chapter(str(path))
    assert (found.deep.words, found.deep.run_s) == (3, 5.0)
    assert (found.core.words, found.core.run_s) == (2 + 2 + 1 + 1, 1.0)  # the heading and "six" too
