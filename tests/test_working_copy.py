"""Students never lose their work to a course update (tools/working_copy.py, issue 14).

A real git clone of the course stands for the course's repository and another for a student's
install. The student syncs a working copy, edits notebook 00 and runs a cell of their own in a
real kernel; the course then gets a new commit (a changed cell, a new cell, a removed cell, a
cell the student changed too, a changed YAML file, a new notebook); the student pulls and syncs
again. Their edits and outputs must still be there, the course's changes must have arrived, the
one cell both changed must show both versions after a note, and a further sync changes nothing.

Saved or live: every output the copy receives from the course starts with a note saying it is the
reference run's; running a cell replaces it, so an output without the note is the student's own.
A copy made before the notes existed gets them on the outputs still exactly the reference run's.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

from tools import working_copy
from tools.kernels import AsyncPrivateSocketKernelManager

REPO = Path(__file__).resolve().parent.parent
TOOL = REPO / "tools" / "working_copy.py"
WELCOME = "00_welcome.ipynb"
# Cells of notebook 00 (stable ids): the title, a section the student leaves alone, the cell
# after which both the student and the course add a cell, a code cell both change, the quiz heading.
TITLE, PICTURE, WAITING, REMOVE_ALL, QUIZ = "a81201af", "9ebc560f", "5aef8827", "4cca0f94", "e00b61ab"
DIAGRAM = "b2f81273"  # a code cell that needs no ROS (it draws the runtime diagram): the student runs it
STUDENT_CELL = "my-own-cell"
COURSE_CELL = "course-new-cell"


def _as_received(path: Path) -> bytes:
    """A course file as a working copy receives it (notebooks: the reference outputs marked)."""
    if path.suffix != ".ipynb":
        return path.read_bytes()
    with open(path, encoding="utf-8") as handle:
        return working_copy._dumps(working_copy.student_edition(json.load(handle)))


def _reference_cells(path: Path) -> dict[str, bool]:
    """{code cell id: its outputs are marked as the reference run's} for cells with outputs."""
    return {c["id"]: working_copy.is_marked(c) for c in _cells(path)
            if c["cell_type"] == "code" and c.get("outputs")}


def _git(cwd: Path, *args: str) -> str:
    done = subprocess.run(["git", "-c", "user.name=Course", "-c", "user.email=course@example.org",
                           "-c", "init.defaultBranch=main", *args],
                          cwd=cwd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, f"git {' '.join(args)} failed: {done.stderr}"
    return done.stdout


def _sync(course: Path, work: Path) -> str:
    done = subprocess.run([sys.executable, str(TOOL), "--course", str(course / "notebooks"),
                           "--work", str(work)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout


def _cells(path: Path) -> list[dict]:
    with open(path, encoding="utf-8") as handle:
        return json.load(handle)["cells"]


def _by_id(path: Path) -> dict[str, dict]:
    return {cell["id"]: cell for cell in _cells(path)}


def _source(cell: dict) -> str:
    return "".join(cell["source"]) if isinstance(cell["source"], list) else cell["source"]


def _edit(path: Path, change) -> None:
    """Load a notebook with nbformat, let ``change`` edit it, save it (as JupyterLab would)."""
    notebook = nbformat.read(path, as_version=4)
    change(notebook)
    nbformat.write(notebook, path)


def _index(notebook, cell_id: str) -> int:
    return [cell.get("id") for cell in notebook.cells].index(cell_id)


@pytest.fixture
def clones(tmp_path):
    """(the course's repository, the student's install), both real clones of this repository."""
    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    upstream, install = tmp_path / "upstream", tmp_path / "install"
    _git(tmp_path, "clone", "--quiet", str(REPO), str(upstream))
    _git(tmp_path, "clone", "--quiet", str(upstream), str(install))
    return upstream, install


def test_edits_survive_a_course_update(clones, tmp_path):
    upstream, install = clones
    work = tmp_path / "work"

    # 1. First sync: a full copy of the notebooks and their data, and the base beside it.
    _sync(install, work)
    course_files = sorted(p.relative_to(install / "notebooks").as_posix()
                          for p in (install / "notebooks").rglob("*")
                          if p.is_file() and p.name != "conftest.py" and "__pycache__" not in p.parts)
    for name in course_files:
        assert (work / name).read_bytes() == _as_received(install / "notebooks" / name), name
        assert (work / ".course-base" / name).is_file(), name
    assert not (work / "conftest.py").exists()
    # Saved or live: every saved output is marked as the reference run's, and no cell has a count.
    marked = _reference_cells(work / WELCOME)
    assert DIAGRAM in marked and len(marked) >= 10 and all(marked.values()), marked
    assert all(c.get("execution_count") is None for c in _cells(work / WELCOME) if c["cell_type"] == "code")
    first = _by_id(work / WELCOME)[DIAGRAM]["outputs"][0]
    assert "reference run" in first["data"]["text/plain"] and "run this cell" in first["data"]["text/plain"]

    # 2. The student edits notebook 00 and runs a cell of their own in a real kernel.
    def student_edits(notebook):
        title = notebook.cells[_index(notebook, TITLE)]
        title.source += "\n\n*My notes: read this twice.*"
        remove_all = notebook.cells[_index(notebook, REMOVE_ALL)]
        remove_all.source = "# I keep my nodes\nprint(sorted(rt.nodes()))"
        mine = nbformat.v4.new_code_cell("answer = 6 * 7\nprint('my answer is', answer)")
        mine.id = STUDENT_CELL
        notebook.cells.insert(_index(notebook, WAITING) + 1, mine)
        client = NotebookClient(notebook, kernel_name="python3", timeout=60,
                                kernel_manager_class=AsyncPrivateSocketKernelManager,
                                resources={"metadata": {"path": str(work)}})
        with client.setup_kernel():
            client.execute_cell(mine, _index(notebook, STUDENT_CELL))
            diagram = _index(notebook, DIAGRAM)  # a course cell the student runs: its outputs become theirs
            client.execute_cell(notebook.cells[diagram], diagram)

    _edit(work / WELCOME, student_edits)
    ran = _by_id(work / WELCOME)[STUDENT_CELL]
    assert _source({"source": ran["outputs"][0]["text"]}) == "my answer is 42\n", ran["outputs"]
    drawn = _by_id(work / WELCOME)[DIAGRAM]
    assert not working_copy.is_marked(drawn) and drawn["execution_count"] == 2  # live: the note is gone

    # 3. The course changes: one commit upstream, pulled into the student's install.
    def course_update(notebook):
        notebook.cells[_index(notebook, PICTURE)].source += "\n\nUpdated by the course."
        notebook.cells[_index(notebook, REMOVE_ALL)].source = "rt.remove_all()\nprint('all removed')"
        new = nbformat.v4.new_markdown_cell("A paragraph the course added.")
        new.id = COURSE_CELL
        notebook.cells.insert(_index(notebook, WAITING) + 1, new)
        del notebook.cells[_index(notebook, QUIZ)]

    _edit(upstream / "notebooks" / WELCOME, course_update)
    talker_yaml = upstream / "notebooks" / "config" / "talker.yaml"
    talker_yaml.write_text(talker_yaml.read_text() + "# updated by the course\n")
    extra = nbformat.v4.new_notebook()
    extra.cells.append(nbformat.v4.new_markdown_cell("# 11 A new chapter"))
    nbformat.write(extra, upstream / "notebooks" / "11_new.ipynb")
    _git(upstream, "add", "-A")
    _git(upstream, "commit", "--quiet", "-m", "Course update")
    _git(install, "pull", "--quiet", "--ff-only")

    # 4. Sync again.
    report = _sync(install, work)
    assert "00_welcome.ipynb: merged, 1 conflict(s) marked" in report, report
    cells = _cells(work / WELCOME)
    ids = [cell["id"] for cell in cells]
    merged = {cell["id"]: cell for cell in cells}
    # the student's edits and outputs are still there
    assert _source(merged[TITLE]).endswith("*My notes: read this twice.*")
    assert merged[STUDENT_CELL]["outputs"] == ran["outputs"]
    assert merged[DIAGRAM]["outputs"] == drawn["outputs"]  # the student's run stays unmarked
    assert [cell for cell, is_marked in _reference_cells(work / WELCOME).items() if not is_marked] == [
        DIAGRAM, STUDENT_CELL]  # every other saved output is still marked as the reference run's
    # the course's changes arrived: a changed cell, a new cell in its place, a removed cell
    assert _source(merged[PICTURE]).endswith("Updated by the course.")
    assert ids[ids.index(WAITING) + 1: ids.index(WAITING) + 3] in (
        [COURSE_CELL, STUDENT_CELL], [STUDENT_CELL, COURSE_CELL])
    assert QUIZ not in ids
    # the cell both changed: a note, the student's version, then the course's version
    at = ids.index(REMOVE_ALL)
    note, ours, theirs = cells[at - 1], cells[at], cells[at + 1]
    assert "course-update-conflict" in note["metadata"]["tags"]
    assert _source(ours) == "# I keep my nodes\nprint(sorted(rt.nodes()))"
    assert _source(theirs) == "rt.remove_all()\nprint('all removed')"
    nbformat.validate(nbformat.read(work / WELCOME, as_version=4))
    # other files: the new notebook and the changed YAML arrived; untouched notebooks equal the course's
    assert (work / "11_new.ipynb").read_bytes() == (install / "notebooks" / "11_new.ipynb").read_bytes()
    assert (work / "config" / "talker.yaml").read_text().endswith("# updated by the course\n")
    for name in course_files:
        if name != WELCOME:
            assert (work / name).read_bytes() == _as_received(install / "notebooks" / name), name

    # 5. Nothing new upstream: a sync changes nothing (the student may keep working).
    before = {p: p.read_bytes() for p in work.rglob("*") if p.is_file()}
    _sync(install, work)
    assert before == {p: p.read_bytes() for p in work.rglob("*") if p.is_file()}

    # 6. Resolving the conflict sticks; a deleted notebook comes back fresh.
    def resolve(notebook):
        for cell_id in (note["id"], theirs["id"]):
            del notebook.cells[_index(notebook, cell_id)]

    _edit(work / WELCOME, resolve)
    os.remove(work / "03_topics.ipynb")
    _sync(install, work)
    ids_after = [cell["id"] for cell in _cells(work / WELCOME)]
    assert note["id"] not in ids_after and theirs["id"] not in ids_after and REMOVE_ALL in ids_after
    assert (work / "03_topics.ipynb").read_bytes() == _as_received(install / "notebooks" / "03_topics.ipynb")


def test_a_changed_data_file_is_never_overwritten(clones, tmp_path):
    upstream, install = clones
    work = tmp_path / "work"
    _sync(install, work)
    (work / "config" / "robots.yaml").write_text("# mine\n")
    robots = upstream / "notebooks" / "config" / "robots.yaml"
    robots.write_text(robots.read_text() + "# course\n")
    _git(upstream, "commit", "--quiet", "-am", "robots")
    _git(install, "pull", "--quiet", "--ff-only")
    report = _sync(install, work)
    assert "robots.yaml.course-update" in report, report
    assert (work / "config" / "robots.yaml").read_text() == "# mine\n"
    assert (work / "config" / "robots.yaml.course-update").read_text().endswith("# course\n")


def test_an_older_copy_gets_the_reference_outputs_marked_and_keeps_the_students(clones, tmp_path):
    _upstream, install = clones
    course, work = install / "notebooks", tmp_path / "work"
    # A copy made before the notes existed: the course's files as they are, in the copy and its base.
    for path in course.rglob("*"):
        relative = path.relative_to(course)
        if path.is_file() and path.name != "conftest.py" and "__pycache__" not in relative.parts:
            for target in (work / relative, work / ".course-base" / relative):
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(path, target)

    def student_work(notebook):  # edits a cell, runs a course cell and a cell of their own
        notebook.cells[_index(notebook, TITLE)].source += "\n\nMine."
        mine = nbformat.v4.new_code_cell("print('mine')")
        mine.id = STUDENT_CELL
        notebook.cells.insert(_index(notebook, WAITING) + 1, mine)
        client = NotebookClient(notebook, kernel_name="python3", timeout=60,
                                kernel_manager_class=AsyncPrivateSocketKernelManager,
                                resources={"metadata": {"path": str(work)}})
        with client.setup_kernel():
            # their own cell first: the diagram's count (2) then differs from the reference run's (1)
            for cell_id in (STUDENT_CELL, DIAGRAM):
                client.execute_cell(notebook.cells[_index(notebook, cell_id)], _index(notebook, cell_id))

    _edit(work / WELCOME, student_work)
    before = _by_id(work / WELCOME)
    assert not any(_reference_cells(work / WELCOME).values())  # nothing is marked yet

    report = _sync(install, work)
    assert "00_welcome.ipynb: updated (" in report and "marked as the reference run's" in report, report
    after = _by_id(work / WELCOME)
    marks = _reference_cells(work / WELCOME)
    unmarked = sorted(cell for cell, is_marked in marks.items() if not is_marked)
    assert unmarked == sorted([DIAGRAM, STUDENT_CELL])
    for cell_id in (DIAGRAM, STUDENT_CELL):  # the student's runs: untouched
        assert after[cell_id]["outputs"] == before[cell_id]["outputs"], cell_id
        assert after[cell_id]["execution_count"] == before[cell_id]["execution_count"], cell_id
    assert _source(after[TITLE]).endswith("Mine.")
    for cell_id, is_marked in marks.items():  # the reference run's: the same outputs behind the note
        if is_marked:
            assert after[cell_id]["outputs"][1:] == working_copy.student_edition(
                {"cells": [before[cell_id]]})["cells"][0]["outputs"][1:], cell_id
    # Notebooks the student never opened are now exactly what a new copy receives.
    assert (work / "03_topics.ipynb").read_bytes() == _as_received(course / "03_topics.ipynb")
    # A second sync changes nothing.
    files = {p: p.read_bytes() for p in work.rglob("*") if p.is_file()}
    _sync(install, work)
    assert files == {p: p.read_bytes() for p in work.rglob("*") if p.is_file()}
