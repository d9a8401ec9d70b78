"""Each chapter's core path: the prose a student reads and the cells they run, without the deep dives.

``python -m tools.reading_path`` prints, per notebook, the words of prose and the seconds of cell run
time on the core path and off it, and an estimate of the core path's minutes: prose read at 200 words
a minute, plus the cells' run time (recorded by ``tools/execute_notebooks.py`` in each code cell's
``metadata.course_run_s``).

A deep dive is a section whose heading cell carries the tag ``deep-dive`` (it runs to the next heading
of the same or a higher level; JupyterLab shows it collapsed when the heading's metadata has
``jp-MarkdownHeadingCollapsed``), or a single cell with that tag. Code blocks in the prose are not
counted as words: a student scans them.
"""

from __future__ import annotations

import dataclasses
import glob
import json
import os
import re
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEEP_DIVE = "deep-dive"
WORDS_PER_MINUTE = 200
RUN_TIME_KEY = "course_run_s"
HEADING = re.compile(r"^ {0,3}(#{1,6})\s", re.M)
CODE_BLOCK = re.compile(r"```.*?```", re.S)
WORD = re.compile(r"[A-Za-z0-9][A-Za-z0-9'’_-]*")


@dataclasses.dataclass
class Path:
    words: int = 0
    run_s: float = 0.0
    unmeasured: int = 0  # code cells without a recorded run time

    @property
    def minutes(self) -> float:
        return self.words / WORDS_PER_MINUTE + self.run_s / 60


@dataclasses.dataclass
class Chapter:
    name: str
    core: Path
    deep: Path


def heading_level(cell: dict) -> int | None:
    """The level of a markdown cell's highest heading (the fewest ``#``), or None if it has none.

    That is JupyterLab's rule for collapsing: a cell with a heading anywhere in it ends a collapsed
    section of the same or a deeper level, and is shown whole. Headings inside code blocks do not count.
    """
    if cell["cell_type"] != "markdown":
        return None
    levels = [len(hashes) for hashes in HEADING.findall(CODE_BLOCK.sub(" ", "".join(cell["source"])))]
    return min(levels) if levels else None


def prose_words(text: str) -> int:
    return len(WORD.findall(CODE_BLOCK.sub(" ", text)))


def notebook_cells(path: str) -> list[dict]:
    with open(path, encoding="utf-8") as handle:
        return json.load(handle)["cells"]


def walk(cells: list[dict]):
    """Each cell with whether it is in a deep dive: under a tagged heading (until the next heading of
    the same or a higher level) or tagged itself."""
    deep_level = None  # the level of the deep-dive heading we are under, if any
    for cell in cells:
        level = heading_level(cell)
        tags = cell.get("metadata", {}).get("tags", [])
        if level is not None and deep_level is not None and level <= deep_level:
            deep_level = None
        if level is not None and DEEP_DIVE in tags and deep_level is None:
            deep_level = level
        yield cell, deep_level is not None or DEEP_DIVE in tags


def chapter(path: str) -> Chapter:
    """Words and run time of a notebook's core path and of its deep dives."""
    core, deep = Path(), Path()
    for cell, in_deep_dive in walk(notebook_cells(path)):
        where = deep if in_deep_dive else core
        if cell["cell_type"] == "markdown":
            where.words += prose_words("".join(cell["source"]))
        elif cell["cell_type"] == "code":
            seconds = cell.get("metadata", {}).get(RUN_TIME_KEY)
            if seconds is None:
                where.unmeasured += 1
            else:
                where.run_s += seconds
    return Chapter(os.path.splitext(os.path.basename(path))[0], core, deep)


def chapters(paths: list[str] | None = None) -> list[Chapter]:
    return [chapter(p) for p in (paths or sorted(glob.glob(os.path.join(REPO, "notebooks", "*.ipynb"))))]


def table(found: list[Chapter]) -> str:
    lines = [f"{'chapter':<32} {'core words':>10} {'core run':>9} {'core min':>9} "
             f"{'deep words':>10} {'deep run':>9} {'deep min':>9}"]
    for c in found:
        note = f"  ({c.core.unmeasured + c.deep.unmeasured} cells without a run time)" if (
            c.core.unmeasured + c.deep.unmeasured) else ""
        lines.append(f"{c.name:<32} {c.core.words:>10,} {c.core.run_s:>8.0f}s {c.core.minutes:>9.0f} "
                     f"{c.deep.words:>10,} {c.deep.run_s:>8.0f}s {c.deep.minutes:>9.0f}{note}")
    total_core = sum(c.core.minutes for c in found)
    total_deep = sum(c.deep.minutes for c in found)
    lines.append(f"{'all chapters':<32} {'':>10} {'':>9} {total_core:>9.0f} {'':>10} {'':>9} "
                 f"{total_deep:>9.0f}")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    print(table(chapters(argv or None)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
