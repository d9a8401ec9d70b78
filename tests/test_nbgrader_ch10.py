"""Chapter 10 as a graded assignment, end to end with real nbgrader, kernels and robots.

The chapter is released into a temporary course directory (``tools/assignments.py release 10``),
then two students hand it in: one with the reference monitor in the exercise cell, one with a
monitor whose fleet subscription has the default, VOLATILE, QoS. Grading runs the whole chapter
for each in a fresh kernel; the reference must earn every point of the exercise, the wrong one
fewer, with the late-joiner criterion named as the reason.
"""

from __future__ import annotations

import json

import pytest

from .nbgrader_support import (
    BEGIN,
    assert_nothing_left,
    grade_cells,
    grade_students,
    points,
    reason,
    release_course,
    solved,
    student_build,
)

pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]

CHAPTER = "10_capstone"
EXERCISE = "ex1_FleetSafetyMonitor"
CELL_TIMEOUT_S = 90  # the slowest cell of chapter 10 (the exercise's check) takes about 10 s


@pytest.fixture(scope="module")
def course(tmp_path_factory):
    return release_course(tmp_path_factory, "10")


@pytest.fixture(scope="module")
def graded(course, tmp_path_factory):
    course_dir, _ = course
    source = json.loads((course_dir / "source" / CHAPTER / f"{CHAPTER}.ipynb").read_text())
    reference = solved(grade_cells(source)[EXERCISE])
    volatile = reference.replace("self.on_fleet_estop, ESTOP_QOS)", "self.on_fleet_estop, 10)")
    assert volatile != reference, "the reference changed: write the wrong answer anew"
    students = {"alice": {EXERCISE: reference}, "bob": {EXERCISE: volatile}}
    return grade_students(course_dir, students, tmp_path_factory, chapter=CHAPTER,
                          cell_timeout=CELL_TIMEOUT_S)


def test_the_release_holds_the_starting_code_and_no_solution(course):
    course_dir, output = course
    release = json.loads((course_dir / "release" / CHAPTER / f"{CHAPTER}.ipynb").read_text())
    cells = grade_cells(release)
    assert sorted(cells) == [EXERCISE, EXERCISE + "_check"]
    exercise = "".join(cells[EXERCISE]["source"])
    assert "TODO" in exercise and BEGIN not in exercise and "ESTOP_QOS" not in exercise
    check = cells[EXERCISE + "_check"]["metadata"]["nbgrader"]
    assert check["locked"] and check["points"] == 7, check  # one per criterion the reference passed
    text = json.dumps(release)
    assert "show_solution(" not in text and "show_passing_report(" not in text
    assert student_build.find_solutions(course_dir / "source")  # the grep below is not empty-handed
    assert student_build.find_solutions(course_dir / "release") == []
    assert "10_capstone: reference solutions pass" in output


def test_the_reference_earns_every_point_and_a_volatile_subscription_fewer(graded):
    rows, log, out, output = graded
    most = float(rows["alice"]["max"])
    assert points(rows, "alice", EXERCISE) == most == 7, output
    assert reason(rows, "alice", EXERCISE) == ""
    assert points(rows, "bob", EXERCISE) < most
    assert "a robot whose safety monitor starts after the fleet stop is stopped too" in reason(
        rows, "bob", EXERCISE)
    for student in ("alice", "bob"):
        assert "fleet-wide e-stop" in (out / "feedback" / f"{student}.html").read_text()


def test_nothing_of_the_grading_is_left(graded):
    rows, log, out, _ = graded
    assert_nothing_left(log)
    print(f"grading seconds per submission: { {s: e['seconds'] for s, e in log.items()} }")
