"""The release check's reading of a lesson cell (``tools.assignments.lesson_cell_problem``).

``make release`` runs the instructor's source in a fresh kernel before it releases a chapter. A lesson
cell, one outside the exercises, that raised keeps the chapter back: the assignment would not run. A
lesson's timing claim that did not pass is the exception: it says how fast this machine was, not
whether the assignment runs, so it is printed as a note. The errors here are the real exceptions the
course's verdicts raise, recorded as a kernel records them (by the exception's type name).
"""

from __future__ import annotations

from course_helpers.core.machine_load import MachineLoad
from course_helpers.core.verdict import FAIL, INCONCLUSIVE, TimingVerdictError, Verdict, VerdictError
from tools.assignments import lesson_cell_problem

QUIET = MachineLoad(cores=2, seconds=1.0, others_cores=0.1, load_per_core=0.1)
BUSY = MachineLoad(cores=2, seconds=1.0, others_cores=1.9, load_per_core=1.5, starved_share=0.4)


def _raised(verdict: Verdict) -> VerdictError:
    try:
        verdict.raise_unless_passed()
    except VerdictError as error:
        return error
    raise AssertionError(f"{verdict} did not raise")


def _cell(error: BaseException, tags: tuple[str, ...] = ()) -> dict:
    """A code cell whose run ended in ``error``, as nbclient leaves it in the notebook."""
    output = {"output_type": "error", "ename": type(error).__name__, "evalue": str(error), "traceback": []}
    return {"cell_type": "code", "metadata": {"tags": list(tags)}, "outputs": [output], "source": ""}


def test_a_timing_verdict_raises_its_own_error_and_a_verdict_by_construction_does_not():
    assert type(_raised(Verdict("the talker keeps 10 Hz", FAIL, "4.2 Hz", QUIET))) is TimingVerdictError
    assert type(_raised(Verdict("every sample arrived", FAIL, "9 of 10"))) is VerdictError


def test_a_lesson_cells_timing_claim_is_a_note_and_does_not_keep_the_chapter_back():
    for outcome, load in ((FAIL, QUIET), (INCONCLUSIVE, BUSY)):
        error = _raised(Verdict("the talker keeps 10 Hz", outcome, "4.2 Hz", load))
        problem, note = lesson_cell_problem(7, _cell(error))
        assert problem is None, problem
        assert note.startswith("note: cell 7's timing claim did not pass (not part of the assignment)"), note
        assert "the talker keeps 10 Hz: 4.2 Hz" in note, note


def test_any_other_error_in_a_lesson_cell_keeps_the_chapter_back():
    by_construction = _raised(Verdict("every sample arrived", FAIL, "9 of 10"))
    assert lesson_cell_problem(3, _cell(by_construction)) == (
        "cell 3 raised VerdictError: \u2718 every sample arrived: 9 of 10", None)
    assert lesson_cell_problem(4, _cell(NameError("name 'rt' is not defined"))) == (
        "cell 4 raised NameError: name 'rt' is not defined", None)


def test_a_cell_that_raises_on_purpose_or_ran_cleanly_is_no_problem():
    assert lesson_cell_problem(5, _cell(ValueError("shown on purpose"), tags=("raises-exception",))) == (
        None, None)
    assert lesson_cell_problem(6, {"cell_type": "code", "metadata": {}, "outputs": [], "source": ""}) == (
        None, None)
