"""Quizzes (course_helpers.notebook.quiz) and the exercise checker report (course_helpers.checks)."""

from __future__ import annotations

import glob
import html
import json
import os

import pytest

from course_helpers import CourseError, WaitTimeout
from course_helpers.checks import CheckReport, Criterion
from course_helpers.notebook.quiz import Choice, Question, Quiz


def make_quiz() -> Quiz:
    return Quiz("Chapter 01 <graph>", [
        Question("Which process must run before ROS 2 nodes can find each other?", [
            Choice("roscore", False, "That was ROS 1's master; ROS 2 has none."),
            Choice("None: discovery is peer to peer", True, "Right: DDS participants announce themselves."),
        ]),
        Question("What does a topic carry?", [
            Choice("Requests & replies", False, "That's a service (request -> response)."),
            Choice("Messages of one type", True, "Yes: every publisher & subscriber agree on the type."),
            Choice("Goals with feedback", False, "That's an action."),
        ]),
    ])


# ---------------------------------------------------------------------- quiz
def test_a_question_needs_a_correct_choice():
    with pytest.raises(CourseError, match="no correct choice"):
        Question("Pick one", [Choice("a", False, "no"), Choice("b", False, "no")])


def test_a_question_needs_two_choices():
    with pytest.raises(CourseError, match="at least 2 choices"):
        Question("Pick one", [Choice("a", True, "yes")])
    with pytest.raises(CourseError, match="at least 2 choices"):
        Question("Pick one", [])


def test_a_quiz_needs_questions_and_choices_of_the_right_kind():
    with pytest.raises(CourseError, match="at least one question"):
        Quiz("Empty", [])
    with pytest.raises(CourseError, match="Choice"):
        Question("Pick one", [("a", True, "yes"), ("b", False, "no")])
    with pytest.raises(CourseError, match="Question"):
        Quiz("Bad", ["not a question"])


def test_answer_returns_the_choice_with_its_feedback_and_grade_counts():
    quiz = make_quiz()
    assert quiz.grade() == (0, 2)
    picked = quiz.answer(0, 0)
    assert not picked.correct and picked.feedback.startswith("That was ROS 1")
    assert quiz.grade() == (0, 2)
    assert quiz.answer(0, 1).correct
    assert quiz.grade() == (1, 2)  # a new pick replaces the old one
    assert quiz.answer(1, 1).correct
    assert quiz.grade() == (2, 2)
    assert quiz.answer(1, 2).feedback == "That's an action."
    assert quiz.grade() == (1, 2)


@pytest.mark.parametrize("question, choice", [(2, 0), (-1, 0), (0, 2), (0, -1), (1, 3)])
def test_answer_rejects_out_of_range_picks(question, choice):
    quiz = make_quiz()
    with pytest.raises(CourseError, match="must be 0.."):
        quiz.answer(question, choice)
    assert quiz.grade() == (0, 2)


def test_as_text_marks_the_correct_answers():
    text = make_quiz().as_text()
    assert text.splitlines() == [
        "Quiz: Chapter 01 <graph> (2 questions)",
        "1. Which process must run before ROS 2 nodes can find each other?",
        "   [ ] roscore",
        "   [x] None: discovery is peer to peer",
        "2. What does a topic carry?",
        "   [ ] Requests & replies",
        "   [x] Messages of one type",
        "   [ ] Goals with feedback",
    ]


def test_as_html_contains_every_question_choice_and_feedback_escaped():
    quiz = make_quiz()
    page = quiz.as_html()
    assert "Chapter 01 &lt;graph&gt;" in page and "<graph>" not in page
    for question in quiz.questions:
        assert html.escape(question.prompt) in page
        for choice in question.choices:
            assert html.escape(choice.text) in page
            assert html.escape(choice.feedback) in page
    assert page.count("&#10004;") == 2  # one correct answer per question
    assert page.count("&#10008;") == 3


def test_the_widget_updates_feedback_and_score_when_a_button_is_clicked():
    quiz = make_quiz()
    view = quiz.widget()
    title, score, prompt1, choices1, feedback1, prompt2, choices2, feedback2 = view.children
    assert "Chapter 01 &lt;graph&gt;" in title.value
    assert "Which process" in prompt1.value and "What does a topic carry" in prompt2.value
    assert [b.description for b in choices2.children] == [
        "Requests & replies", "Messages of one type", "Goals with feedback"]
    assert score.value == "<i>Score: 0 / 2</i>"
    assert feedback1.value == ""

    choices1.children[0].click()
    assert "Not quite." in feedback1.value
    assert html.escape("That was ROS 1's master; ROS 2 has none.") in feedback1.value
    assert choices1.children[0].button_style == "danger"
    assert score.value == "<i>Score: 0 / 2</i>"

    choices1.children[1].click()
    assert "Correct." in feedback1.value
    assert [b.button_style for b in choices1.children] == ["", "success"]
    assert score.value == "<i>Score: 1 / 2</i>"

    choices2.children[1].click()
    assert html.escape("every publisher & subscriber") in feedback2.value
    assert "Correct." in feedback2.value and "DDS participants" in feedback1.value  # one feedback each
    assert score.value == "<i>Score: 2 / 2</i>"
    assert quiz.grade() == (2, 2)


def test_long_choices_are_shortened_on_buttons_with_the_full_text_as_tooltip():
    long_text = "a" * 200
    quiz = Quiz("Long", [Question("?", [Choice(long_text, True, "ok"), Choice("b", False, "no")])])
    button = quiz.widget().children[3].children[0]
    assert len(button.description) == 90 and button.description.endswith("…")
    assert button.tooltip == long_text


def test_the_display_bundle_has_text_html_and_a_widget():
    from IPython.core.formatters import DisplayFormatter  # noqa: F401 (IPython is installed)

    quiz = make_quiz()
    bundle = {"text/plain": quiz.as_text(), "text/html": quiz.as_html(), **quiz._widget_bundle()}
    assert "application/vnd.jupyter.widget-view+json" in bundle
    assert bundle["text/plain"].startswith("Quiz: Chapter 01")


# ---------------------------------------------------------------------- checks
def test_a_report_passes_only_when_every_criterion_passed():
    report = CheckReport("Exercise 3.1: a talker")
    assert not report.passed  # nothing checked yet
    assert report.add("publishes on /chatter", True, "got 5 messages") is True
    assert report.passed
    assert report.add("publishes at 2 Hz", False, "measured 0.5 Hz", "timer period is in seconds") is False
    assert not report.passed
    assert report.criteria[1] == Criterion("publishes at 2 Hz", False, "measured 0.5 Hz",
                                           "timer period is in seconds")
    assert report.add("truthy values count", 1) is True and report.criteria[-1].passed is True


def test_run_returns_the_result_or_turns_an_exception_into_a_failed_criterion():
    report = CheckReport("Exercise")
    assert report.run("builds the node", lambda: 42) == 42
    assert report.criteria == []  # a step that works adds nothing by itself

    def broken():
        raise WaitTimeout("timed out after 2 s waiting for 1 message(s) on /chatter")

    assert report.run("receives a message", broken, hint="publish from a timer") is None
    (criterion,) = report.criteria
    assert criterion.name == "receives a message" and not criterion.passed
    assert criterion.detail == "WaitTimeout: timed out after 2 s waiting for 1 message(s) on /chatter"
    assert criterion.hint == "publish from a timer"
    assert not report.passed


def test_run_keeps_the_error_itself_when_the_exception_has_notes():
    def noted():
        error = ValueError("rate_hz must be > 0")
        error.add_note("raised in Talker.__init__")
        raise error

    report = CheckReport("Exercise")
    report.run("creates the node", noted)
    assert report.criteria[0].detail.startswith("ValueError: rate_hz must be > 0")


def test_summary_lists_criteria_with_details_and_hints_of_failures():
    report = CheckReport("Exercise 3.1")
    report.add("publishes on /chatter", True, "5 messages", hint="not shown when passed")
    report.add("uses a timer", False, hint="create_timer(period_s, callback)")
    assert report.summary().splitlines() == [
        "Exercise 3.1: NOT YET (1/2 criteria)",
        "  [pass] publishes on /chatter - 5 messages",
        "  [FAIL] uses a timer",
        "         hint: create_timer(period_s, callback)",
    ]
    assert str(report) == report.summary()
    passed = CheckReport("Exercise 3.2")
    passed.add("works", True)
    assert passed.summary() == "Exercise 3.2: PASSED (1/1 criteria)\n  [pass] works"


def test_html_rendering_colours_marks_and_escapes():
    report = CheckReport("Exercise <3.1>")
    report.add("publishes <String>", True, "a & b")
    report.add("uses a timer", False, "sleep() found", "use create_timer, not time.sleep")
    page = report._repr_html_()
    assert "Exercise &lt;3.1&gt;: not passed yet" in page
    assert "publishes &lt;String&gt;" in page and "a &amp; b" in page
    assert page.count("&#10004;") == 1 and page.count("&#10008;") == 1
    assert "#1a7f37" in page and "#cf222e" in page
    assert "Hint: use create_timer, not time.sleep" in page
    good = CheckReport("Exercise 3.2")
    good.add("works", True, hint="hidden when passed")
    assert "passed</b>" in good._repr_html_() and "Hint" not in good._repr_html_()


def test_pretty_printing_uses_the_summary():
    from IPython.lib.pretty import pretty

    report = CheckReport("Exercise")
    report.add("works", True)
    assert pretty(report) == report.summary()


def test_every_chapter_notebook_has_a_quiz_that_ran():
    """Each chapter (01 onwards, the lab 08b included) has a quiz cell that runs without error."""
    notebooks = sorted(glob.glob(os.path.join(os.path.dirname(__file__), "..", "notebooks", "[01]*.ipynb")))
    chapters = [p for p in notebooks if not os.path.basename(p).startswith("00_")]
    assert len(chapters) >= 11
    for path in chapters:
        with open(path, encoding="utf-8") as handle:
            cells = json.load(handle)["cells"]
        quiz_cells = [c for c in cells if c["cell_type"] == "code" and "Quiz(" in "".join(c["source"])]
        assert quiz_cells, f"{os.path.basename(path)} has no quiz"
        outputs = quiz_cells[-1].get("outputs", [])
        assert outputs and all(o["output_type"] != "error" for o in outputs), os.path.basename(path)


def _environment_criteria(env_changes: dict[str, str | None]) -> dict[str, bool]:
    """Chapter 00's environment check in a fresh process with ``env_changes``: passed, by criterion."""
    import json
    import os
    import subprocess
    import sys

    env = dict(os.environ)
    for key, value in env_changes.items():
        env.pop(key, None) if value is None else env.__setitem__(key, value)
    code = ("import json; from course_helpers import get_runtime; "
            "from course_helpers.checks.ch00_environment import check_environment; "
            "rt = get_runtime(); report = check_environment(rt); "
            "print(json.dumps({c.name: c.passed for c in report.criteria})); rt.stop()")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_environment_check_passes_a_kernel_with_its_own_reserved_domain():
    criteria = _environment_criteria({"ROS_DOMAIN_ID": None})
    assert criteria["this kernel has its own ROS domain"], criteria


def test_the_environment_check_fails_a_kernel_on_a_domain_set_by_hand():
    criteria = _environment_criteria({"ROS_DOMAIN_ID": "0"})
    assert not criteria["this kernel has its own ROS domain"], criteria
