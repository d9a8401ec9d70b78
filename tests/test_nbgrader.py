"""Graded assignments end to end with real nbgrader and real ROS nodes (``tools/assignments.py``).

Chapter 04 (two exercises, real service nodes) is released into a temporary course directory
with nbgrader's own generate_assignment, then three students hand it in: one correct, one
unchanged (wrong) with a cell of its own that starts a daemon, and one whose first exercise hangs.
Grading must give the hanging exercise zero with its reason, still grade the other exercise,
sweep the daemon and leave nothing behind. ``test_nbgrader_misbehaving.py`` grades the kernels
that die, flood or run away, and a run past the wall clock, on another worker at the same time.
"""

from __future__ import annotations

import json

import pytest

from .nbgrader_support import (
    BEGIN,
    CHAPTER,
    EX1,
    EX2,
    EXTRA,
    HANGS,
    LAST_CELL,
    assert_nothing_left,
    grade_cells,
    graded_students,
    points,
    reason,
    released_course,
    results,
    solutions,
    source,
    student_build,
    verdict,
)

pytestmark = [pytest.mark.slow, pytest.mark.grades_notebooks, pytest.mark.timeout(600)]


def _students(course_dir) -> dict:
    solved = solutions(course_dir)
    return {
        "alice": solved,
        "bob": {EXTRA: LAST_CELL},  # hands in the starting code, and a process outside any exercise
        "carol": {EX1: HANGS, EX2: solved[EX2]},
    }


course = released_course()
graded = graded_students(_students)


def test_every_exercise_of_the_notebooks_gets_its_reference_solution():
    """Static, for every chapter: each exercise found has a reference solution, and the source's
    solution and test cells are valid Python (what release would validate by running them)."""
    found = {}
    for path in source.chapter_notebooks():
        chapter = source.load_chapter(path)
        assert [e.grade_id for e in chapter.exercises if e.skipped] == [], \
            [(e.grade_id, e.skipped) for e in chapter.exercises]
        nb = source.build_source(chapter, {})
        for cell in nb["cells"]:
            if "nbgrader" in cell["metadata"]:
                lines = "".join(cell["source"]).splitlines()
                compile("\n".join(ln for ln in lines if not ln.startswith("%")), path.name, "exec")
        found[chapter.name] = len(chapter.graded)
    assert found.get(CHAPTER) == 2 and sum(found.values()) >= 10, found


def test_release_holds_no_solution_and_the_checkers_work_without_them(course):
    course_dir, output = course
    release = course_dir / "release" / CHAPTER / f"{CHAPTER}.ipynb"
    cells = grade_cells(json.loads(release.read_text()))
    assert sorted(cells) == sorted([EX1, EX1 + "_check", EX2, EX2 + "_check"])
    for grade_id in (EX1, EX2):
        assert cells[grade_id]["metadata"]["nbgrader"]["solution"]
        assert "TODO" in "".join(cells[grade_id]["source"])  # the starting code stays
        assert BEGIN not in "".join(cells[grade_id]["source"])
        points = cells[grade_id + "_check"]["metadata"]["nbgrader"]["points"]
        assert points >= 3 and cells[grade_id + "_check"]["metadata"]["nbgrader"]["locked"]
    # the grep is not vacuous: the instructor source holds solution lines, the release none
    assert student_build.find_solutions(course_dir / "source")
    assert student_build.find_solutions(course_dir / "release") == []
    build = course_dir / "student_build"
    assert (build / "course_helpers" / "checks").is_dir()
    assert not (build / "course_helpers" / "solutions").exists()
    assert student_build.find_solutions(build) == []
    assert "course_helpers.solutions: absent" in output and "reference solutions pass" in output


def test_scores_reasons_and_feedback(graded):
    rows, log, out, output = graded
    assert sorted(rows) == ["alice", "bob", "carol"]
    max1, max2 = points(rows, "alice", EX1), points(rows, "alice", EX2)
    assert max1 + max2 == float(rows["alice"]["max"]), output  # alice: every point
    assert reason(rows, "alice", EX1) == reason(rows, "alice", EX2) == ""
    for ex, most in ((EX1, max1), (EX2, max2)):  # the starting code passes some criteria, never all
        assert points(rows, "bob", ex) < most
        assert reason(rows, "bob", ex).startswith("failed: "), reason(rows, "bob", ex)
    assert points(rows, "carol", EX1) == 0 and "CellTimeoutError" in reason(rows, "carol", EX1)
    # the misbehaving exercise costs only itself: the correct second exercise still earns its points
    assert points(rows, "carol", EX2) == max2, reason(rows, "carol", EX2)
    for student in rows:
        html = (out / "feedback" / f"{student}.html").read_text()
        assert "Exercise 04.1" in html and "Exercise 04.2" in html
    assert "CellTimeoutError" in (out / "feedback" / "carol.html").read_text()
    # a process started outside the exercises outlives the kernel: the sweep kills it and says so
    assert "killed 1 process(es) left after the run" in rows["bob"]["notes"]
    assert "sleep 700" in rows["bob"]["notes"]


def test_grade_alls_verdict_on_this_grade_table(course, graded):
    """``grade-all``'s verdict (``tools.grading.verdict``) on this real table: alice's reference and bob's
    starting code are right; carol taken for a reference, or alice for starting code, is caught."""
    course_dir, _ = course
    rows, _, out, _ = graded
    release = grade_cells(json.loads((course_dir / "release" / CHAPTER / f"{CHAPTER}.ipynb").read_text()))
    tests = (EX1 + "_check", EX2 + "_check")
    max_points = {g: float(release[g]["metadata"]["nbgrader"]["points"]) for g in tests}
    table = results.read_csv(out / "grades.csv", max_points)

    def problems(starting: str, reference: str) -> list[str]:
        return verdict.problems(verdict.judge(CHAPTER, max_points, table, starting, reference))

    assert problems(starting="bob", reference="alice") == []
    hung = problems(starting="bob", reference="carol")
    assert len(hung) == 1 and hung[0].startswith(f"{CHAPTER}, {EX1}: the reference scored 0/"), hung
    assert "CellTimeoutError" in hung[0]
    assert problems(starting="alice", reference="alice") == [
        f"{CHAPTER}, {ex}: the starting code was not marked down ({m:g}/{m:g}): the checker accepts it"
        for ex, m in ((EX1, max_points[tests[0]]), (EX2, max_points[tests[1]]))]


def test_nothing_of_a_run_is_left(graded):
    rows, log, out, _ = graded
    assert_nothing_left(log)
    print(f"grading seconds per submission: { {s: e['seconds'] for s, e in log.items()} }")
