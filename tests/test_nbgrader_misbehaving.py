"""Grading survives kernels that misbehave, with real nbgrader and real ROS nodes.

Chapter 04 is released into a course directory of this file's own (``test_nbgrader.py`` grades the
correct, unchanged and hanging submissions on another worker meanwhile). Two students hand in code
that kills the kernel, or floods the output in one exercise and leaves a detached process in the
other; a third is graded with a wall clock shorter than its run, and a fourth's hang is cut beside
busy processes. Each misbehaving exercise scores zero with its reason, the other exercise is still
graded, and nothing of any run is left.
"""

from __future__ import annotations

import pytest

from tools.busy_loops import busy_loops

from .nbgrader_support import (
    CRASHES,
    EX1,
    EX2,
    FLOODS,
    HANGS,
    RUNAWAY_LINE,
    assert_no_process_left,
    assert_nothing_left,
    grade,
    graded_students,
    hand_in,
    points,
    reason,
    released_course,
    solutions,
)

pytestmark = [pytest.mark.slow, pytest.mark.grades_notebooks, pytest.mark.timeout(600)]


def _students(course_dir) -> dict:
    solved = solutions(course_dir)
    # the reference class comes after the starting code in the cell: change the reference
    head, tail = solved[EX2].rsplit("        super().__init__('sum_relay')\n", 1)
    runaway = f"import subprocess\n{head}        super().__init__('sum_relay')\n{RUNAWAY_LINE}{tail}"
    return {
        "dave": {EX1: CRASHES, EX2: solved[EX2]},
        "erin": {EX1: FLOODS, EX2: runaway},
    }


course = released_course()
graded = graded_students(_students)


def test_a_dead_flooding_or_runaway_exercise_scores_zero_with_its_reason(graded):
    rows, log, out, output = graded
    assert sorted(rows) == ["dave", "erin"], output
    assert points(rows, "dave", EX1) == 0 and "KernelDied" in reason(rows, "dave", EX1)
    assert points(rows, "erin", EX1) == 0 and "OutputLimitExceeded" in reason(rows, "erin", EX1)
    assert points(rows, "erin", EX2) == 0 and "RunawayProcesses" in reason(rows, "erin", EX2)
    assert "sleep 600" in reason(rows, "erin", EX2)
    # the dead kernel costs only its exercise: the correct second exercise still earns every point
    assert points(rows, "dave", EX2) > 0 and reason(rows, "dave", EX2) == "", reason(rows, "dave", EX2)
    assert any(e["kind"] == "kernel restarted" for e in log["dave"]["events"])
    assert "KernelDied" in (out / "feedback" / "dave.html").read_text()
    assert "OutputLimitExceeded" in (out / "feedback" / "erin.html").read_text()


def test_nothing_of_a_run_is_left(graded):
    rows, log, out, _ = graded
    assert_nothing_left(log)
    print(f"grading seconds per submission: { {s: e['seconds'] for s, e in log.items()} }")


def test_a_run_past_the_wall_clock_scores_zero_and_is_swept(course, tmp_path_factory):
    """The wall clock stops nbgrader itself mid-run: every exercise scores zero with that reason,
    and nothing of the run is left (the orphaned kernel notices and exits, or the sweep kills it)."""
    course_dir, _ = course
    answers = {EX1: HANGS, EX2: solutions(course_dir)[EX2]}  # runs at least CELL_TIMEOUT_S
    submissions = hand_in(course_dir, {"frank": answers}, tmp_path_factory.mktemp("late"))
    rows, log, output = grade(course_dir, submissions, course_dir / "graded-late", wall_clock=20)
    frank = rows["frank"]
    for ex in (EX1, EX2):
        assert float(frank[ex + "_check"]) == 0
        assert "wall clock of 20 s" in frank[ex + "_check reason"], output
    entry = log["frank"]
    # How far the run got before the wall clock stopped it depends on the machine's speed: on a slow
    # one, the kernel had not yet taken its domain (seen in CI: 'domains' empty). Whatever it took must
    # be free again; that a graded kernel takes one at all is test_nothing_of_a_run_is_left's to show.
    assert entry["domains_still_held"] == [], entry
    assert entry["tmp_removed"]
    assert_no_process_left(log)


def test_a_timeout_on_a_busy_machine_is_inconclusive_and_still_scores_zero(course, tmp_path_factory):
    """A cell the wall clock cut while the machine was busy may have been slowed, not hung: the reason
    says the timeout is inconclusive, with the load, and the exercise still scores zero (an inconclusive
    verdict is never a pass). The busy machine is two real CPU-bound processes outside the grader."""
    course_dir, _ = course
    answers = {EX1: HANGS, EX2: solutions(course_dir)[EX2]}
    submissions = hand_in(course_dir, {"gina": answers}, tmp_path_factory.mktemp("busy"))
    with busy_loops(2):
        rows, log, output = grade(course_dir, submissions, course_dir / "graded-busy", wall_clock=600,
                                  cell_timeout=10)
    why = reason(rows, "gina", EX1)
    assert points(rows, "gina", EX1) == 0 and "CellTimeoutError" in why, output
    assert "Inconclusive: this machine was busy while it ran (other processes used " in why, why
    assert any(e["kind"] == "timeout on a busy machine" for e in log["gina"]["events"]), log["gina"]
    assert_no_process_left(log)
