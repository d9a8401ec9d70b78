"""Submissions made from an assignment itself: the reference, the untouched starting code, any answers.

A student's submission is the released notebook with their code in its exercise (solution) cells.
:func:`reference_answers` reads the finished exercises from the instructor source (the starting
code and the reference solution, without nbgrader's markers), and :func:`hand_in` writes a
submission in the layout ``tools/assignments.py grade`` reads (``<student>/<assignment>/<assignment>.ipynb``).
The tests and ``grade-all`` make their students this way.
"""

from __future__ import annotations

import json
from pathlib import Path

from tools.grading.source import BEGIN, END

EXTRA_CELL = "extra cell"  # an answer under this key is a cell the student added at the end


def grade_cells(nb: dict) -> dict[str, dict]:
    """grade id -> cell, for every cell nbgrader knows (solution and test cells)."""
    return {c["metadata"]["nbgrader"]["grade_id"]: c for c in nb["cells"] if "nbgrader" in c["metadata"]}


def solved(source_cell: dict) -> str:
    """A finished exercise: the instructor source's cell (starting code, then the reference) without
    nbgrader's ``### BEGIN/END SOLUTION`` markers, as one cell."""
    src = source_cell["source"]
    lines = ("".join(src) if isinstance(src, list) else src).splitlines()
    return "\n".join(line for line in lines if line.strip() not in (BEGIN, END)) + "\n"


def _notebook(course_dir: Path, folder: str, assignment: str) -> dict:
    return json.loads((course_dir / folder / assignment / f"{assignment}.ipynb").read_text(encoding="utf-8"))


def reference_answers(course_dir: Path, assignment: str) -> dict[str, str]:
    """Exercise grade id -> its finished cell, for every exercise of a generated assignment."""
    cells = grade_cells(_notebook(course_dir, "source", assignment))
    return {grade_id: solved(cell) for grade_id, cell in cells.items()
            if cell["metadata"]["nbgrader"].get("solution")}


def hand_in(course_dir: Path, assignment: str, students: dict[str, dict[str, str]],
            submissions: Path) -> Path:
    """Write each student's notebook under ``submissions``: the release with their answers (grade id ->
    cell source; ``EXTRA_CELL`` -> a code cell added at the end) in place. An empty dict of answers
    hands in the starting code untouched. Returns ``submissions``."""
    release = _notebook(course_dir, "release", assignment)
    for student, answers in students.items():
        nb = json.loads(json.dumps(release))
        cells = grade_cells(nb)
        unknown = set(answers) - set(cells) - {EXTRA_CELL}
        if unknown:
            raise ValueError(f"{assignment} has no cell {sorted(unknown)}; "
                             f"its graded cells are {sorted(cells)}")
        for grade_id, cell in cells.items():
            if grade_id in answers:
                cell["source"] = answers[grade_id]
        if EXTRA_CELL in answers:
            nb["cells"].append({"cell_type": "code", "execution_count": None, "id": "student-extra",
                                "metadata": {}, "outputs": [], "source": answers[EXTRA_CELL]})
        folder = submissions / student / assignment
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"{assignment}.ipynb").write_text(json.dumps(nb, indent=1), encoding="utf-8")
    return submissions
