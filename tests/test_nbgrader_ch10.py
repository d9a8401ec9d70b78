"""Chapter 10 as a graded assignment, end to end with real nbgrader, kernels and robots.

The chapter is released into a temporary course directory (``tools/assignments.py release 10``).
Releasing runs the whole instructor notebook, reference monitor included, in a fresh kernel with the
student build, and gives the check cell one point per criterion that reference passed: so the release
itself proves that the reference earns every point (7, each criterion of the checker).

Then one student hands it in with a monitor whose fleet subscription has the default, VOLATILE, QoS,
and real nbgrader grades the whole chapter in a fresh kernel: that monitor must earn fewer points, with
the late-joiner criterion named as the reason. (Grading the reference a second time, as a student,
would run the same chapter again for what the release has shown; it cost about 85 s.)
"""

from __future__ import annotations

import json

import pytest

from .nbgrader_support import (
    BEGIN,
    assert_nothing_left,
    grade_cells,
    graded_students,
    points,
    reason,
    released_course,
    solved,
    student_build,
)

pytestmark = [pytest.mark.slow, pytest.mark.grades_notebooks, pytest.mark.timeout(900)]

CHAPTER = "10_capstone"
EXERCISE = "ex1_FleetSafetyMonitor"
CELL_TIMEOUT_S = 90  # the slowest cell of chapter 10 (the exercise's check) takes about 10 s


def _students(course_dir) -> dict:
    source = json.loads((course_dir / "source" / CHAPTER / f"{CHAPTER}.ipynb").read_text())
    reference = solved(grade_cells(source)[EXERCISE])
    volatile = reference.replace("self.on_fleet_estop, ESTOP_QOS)", "self.on_fleet_estop, 10)")
    assert volatile != reference, "the reference changed: write the wrong answer anew"
    return {"bob": {EXERCISE: volatile}}


course = released_course("10")
graded = graded_students(_students, chapter=CHAPTER, cell_timeout=CELL_TIMEOUT_S)


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
    # the release ran the reference: it passed every criterion, and each became a point
    passed = f"{CHAPTER}: reference solutions pass, points {{'{EXERCISE}_check': 7}}"
    assert passed in output, output


def test_a_volatile_fleet_subscription_loses_the_late_joiner_point(graded):
    rows, log, out, output = graded
    most = float(rows["bob"]["max"])
    assert most == 7, output  # the points the release gave for the reference's seven criteria
    assert points(rows, "bob", EXERCISE) < most, output
    assert "a robot whose safety monitor starts after the fleet stop is stopped too" in reason(
        rows, "bob", EXERCISE)
    assert "fleet-wide e-stop" in (out / "feedback" / "bob.html").read_text()


def test_nothing_of_the_grading_is_left(graded):
    rows, log, out, _ = graded
    assert_nothing_left(log)
    print(f"grading seconds per submission: { {s: e['seconds'] for s, e in log.items()} }")
