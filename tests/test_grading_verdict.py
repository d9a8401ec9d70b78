"""``make grade-all``'s verdict (``tools/grading/verdict.py``) on a real grade table, in a second.

``data/grade_all_04_services.csv`` is the grade table that ``tools/assignments.py grade-all 04`` wrote
with real nbgrader: chapter 04's untouched starting code and its reference, each graded in a fresh
kernel. The verdict must find it right, and must name the chapter and the exercise when the
reference loses a point, when the starting code is not marked down, or when a run did not finish.
``test_nbgrader.py`` judges its own freshly graded table the same way.
"""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import pytest

from tools.grading import results, verdict

TABLE = Path(__file__).parent / "data" / "grade_all_04_services.csv"
CHAPTER = "04_services"
EX1, EX2 = "ex1_BatteryMonitor", "ex2_SumRelay"
# the points of the two test cells in that run's release (the criteria each reference passes)
MAX_POINTS = {f"{EX1}_check": 8.0, f"{EX2}_check": 7.0}


def _rows() -> list[dict]:
    with open(TABLE, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _write(path: Path, rows: list[dict]) -> Path:
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return path


def judged(tmp_path: Path, change=None) -> list[verdict.Line]:
    """The verdict on the real table, after ``change(rows by student)`` edited a copy of it."""
    path = shutil.copyfile(TABLE, tmp_path / "grades.csv")
    if change:
        rows = _rows()
        change({row["student"]: row for row in rows})
        _write(path, rows)
    return verdict.judge(CHAPTER, MAX_POINTS, results.read_csv(path, MAX_POINTS))


def test_the_real_table_is_right_and_printed(tmp_path):
    assert sorted(row["student"] for row in _rows()) == [verdict.STARTING, verdict.REFERENCE]
    lines = judged(tmp_path)
    assert verdict.problems(lines) == []
    text = verdict.table(lines)
    assert f"| {CHAPTER} | {EX1}" in text and f"| {CHAPTER} | {EX2}" in text
    for line in lines:  # the reference earned every point, the starting code fewer, with a reason
        assert line.reference == (line.max_points, "")
        assert line.starting[0] < line.max_points and line.starting[1].startswith("failed: ")
    assert text.count("| ok ") == 2 and "FAIL" not in text


def test_a_reference_that_loses_points_fails_naming_chapter_and_exercise(tmp_path):
    def lose(rows):
        rows[verdict.REFERENCE][f"{EX2}_check"] = "6"
        rows[verdict.REFERENCE][f"{EX2}_check reason"] = "failed: the relay answered after 2 s"

    lines = judged(tmp_path, lose)
    assert verdict.problems(lines) == [
        f"{CHAPTER}, {EX2}: the reference scored 6/7 (failed: the relay answered after 2 s)"]
    assert "| FAIL" in verdict.table(lines)


def test_a_starting_code_with_full_marks_fails(tmp_path):
    def accept(rows):
        rows[verdict.STARTING][f"{EX1}_check"] = "8"
        rows[verdict.STARTING][f"{EX1}_check reason"] = ""

    assert verdict.problems(judged(tmp_path, accept)) == [
        f"{CHAPTER}, {EX1}: the starting code was not marked down (8/8): the checker accepts it"]


def test_the_reference_handed_in_as_starting_code_is_caught_on_every_exercise():
    graded = results.read_csv(TABLE, MAX_POINTS)
    both = verdict.REFERENCE
    lines = verdict.judge(CHAPTER, MAX_POINTS, graded, starting=both, reference=both)
    assert verdict.problems(lines) == [
        f"{CHAPTER}, {EX1}: the starting code was not marked down (8/8): the checker accepts it",
        f"{CHAPTER}, {EX2}: the starting code was not marked down (7/7): the checker accepts it"]


def test_a_run_that_did_not_finish_fails_although_it_scored_zero(tmp_path):
    """A starting code stopped by the wall clock scores zero everywhere: not to be taken for marked down."""
    reason = f"{results.PAST_WALL_CLOCK} of 900 s and was stopped"

    def stopped(rows):
        for test in MAX_POINTS:
            rows[verdict.STARTING][test] = "0"
            rows[verdict.STARTING][f"{test} reason"] = reason

    assert verdict.problems(judged(tmp_path, stopped)) == [
        f"{CHAPTER}: {verdict.STARTING} was not graded to the end: {reason}"]


def test_a_student_missing_from_the_table_fails(tmp_path):
    rows = [row for row in _rows() if row["student"] != verdict.REFERENCE]
    path = _write(tmp_path / "grades.csv", rows)
    lines = verdict.judge(CHAPTER, MAX_POINTS, results.read_csv(path, MAX_POINTS))
    assert verdict.problems(lines) == [f"{CHAPTER}: {verdict.REFERENCE} was not graded"]


def test_the_graders_notes_are_listed_but_fail_nothing(tmp_path):
    rows = _rows()
    rows[0]["notes"] = "killed 1 process(es) left after the run: pid 7: sleep 700 | domain(s) [5] still held"
    graded = results.read_csv(_write(tmp_path / "grades.csv", rows), MAX_POINTS)
    assert verdict.problems(verdict.judge(CHAPTER, MAX_POINTS, graded)) == []
    assert verdict.notes(CHAPTER, graded) == [
        f"{CHAPTER}, {rows[0]['student']}: killed 1 process(es) left after the run: pid 7: sleep 700",
        f"{CHAPTER}, {rows[0]['student']}: domain(s) [5] still held"]


def test_a_table_without_an_exercise_is_refused():
    with pytest.raises(ValueError, match="ex3_Missing_check"):
        results.read_csv(TABLE, {**MAX_POINTS, "ex3_Missing_check": 5.0})
