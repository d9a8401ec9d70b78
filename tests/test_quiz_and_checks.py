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
            Choice("None: discovery is peer to peer", True, "DDS participants announce themselves."),
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


# A quiz file with one mistake each, and what the error must name.
GOOD_QUESTION = """
  - prompt: Which command lists topics?
    choices:
      - text: ros2 node list
        feedback: That lists nodes.
      - text: ros2 topic list
        correct: true
        feedback: Right.
"""
BAD_QUIZ_FILES = {
    "not YAML": ("title: [unclosed\n", "bad.yaml is not valid YAML"),
    "a list": ("- title: x\n", "bad.yaml: the file must be a mapping with the keys title, questions"),
    "no title": ("questions:" + GOOD_QUESTION, "bad.yaml: the file: missing title"),
    "an unknown key": ("title: T\nanswers: []\nquestions:" + GOOD_QUESTION,
                       "bad.yaml: the file: unknown answers (the keys are title, questions)"),
    "questions not a list": ("title: T\nquestions: 3\n", "bad.yaml: the file: 'questions' must be list"),
    "an empty quiz": ("title: T\nquestions: []\n", "bad.yaml: quiz 'T' needs at least one question"),
    "a question without choices": ("title: T\nquestions:\n  - prompt: P?\n",
                                   "bad.yaml: question 1: missing choices"),
    "an empty prompt": ("title: T\nquestions:" + GOOD_QUESTION.replace("Which command lists topics?", "''"),
                        "bad.yaml: question 1: 'prompt' must be non-empty text, got ''"),
    "a choice with a typo": ("title: T\nquestions:" + GOOD_QUESTION.replace("correct: true", "corect: true"),
                             "bad.yaml: question 1, choice 2: unknown corect"),
    "correct: yes-ish": ("title: T\nquestions:" + GOOD_QUESTION.replace("correct: true", "correct: 'yes'"),
                         "bad.yaml: question 1, choice 2: 'correct' must be true or false, got 'yes'"),
    "no feedback": ("title: T\nquestions:" + GOOD_QUESTION.replace("        feedback: Right.\n", ""),
                    "bad.yaml: question 1, choice 2: missing feedback"),
    "no correct choice": ("title: T\nquestions:" + GOOD_QUESTION.replace("        correct: true\n", ""),
                          "bad.yaml: question 'Which command lists topics?' has no correct choice"),
    "one choice": ("title: T\nquestions:" + GOOD_QUESTION.split("      - text: ros2 topic list")[0]
                   .replace("feedback: That lists nodes.", "correct: true\n        feedback: x"),
                   "bad.yaml: question 'Which command lists topics?' needs at least 2 choices"),
}


def test_a_good_quiz_file_loads(tmp_path):
    path = tmp_path / "good.yaml"
    path.write_text("title: T\nquestions:" + GOOD_QUESTION)
    quiz = Quiz.from_file(path)
    assert quiz.name == "good" and quiz.title == "T"
    assert quiz.questions == [Question("Which command lists topics?", [
        Choice("ros2 node list", False, "That lists nodes."), Choice("ros2 topic list", True, "Right.")])]
    assert Quiz.from_dict(quiz.to_dict()) == Quiz("T", quiz.questions)


@pytest.mark.parametrize("mistake", list(BAD_QUIZ_FILES))
def test_a_quiz_file_with_a_mistake_gets_an_error_naming_the_file_and_the_mistake(tmp_path, mistake):
    text, message = BAD_QUIZ_FILES[mistake]
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(CourseError) as error:
        Quiz.from_file(path)
    assert str(error.value).startswith(message), str(error.value)


@pytest.mark.parametrize("name", ["nope", "../quiz", "03_topics.yaml", None])
def test_loading_a_quiz_that_does_not_exist_names_the_ones_that_do(name):
    with pytest.raises(CourseError, match=r"there is no quiz named .*; the course's quizzes are "
                                          r"00_welcome, 01_architecture, .*10_capstone$"):
        Quiz.load(name)
    with pytest.raises(CourseError, match="cannot read the quiz file"):
        Quiz.from_file("/nonexistent/quiz.yaml")


def test_every_quiz_file_belongs_to_a_notebook_and_every_notebook_has_one():
    notebooks = {os.path.splitext(os.path.basename(p))[0]
                 for p in glob.glob(os.path.join(os.path.dirname(__file__), "..", "notebooks", "*.ipynb"))}
    assert set(Quiz.names()) == notebooks
    for name in Quiz.names():
        assert Quiz.load(name).name == name


def test_no_feedback_repeats_the_verdict_the_quiz_shows_before_it():
    """A pick shows "Correct." or "Not quite." and then the choice's feedback: a feedback that starts
    with a verdict of its own would read "Correct. Right: ..."."""
    verdicts = ("right", "correct", "wrong", "not quite", "yes", "no")
    repeated = [(name, c.feedback) for name in Quiz.names() for q in Quiz.load(name).questions
                for c in q.choices if c.feedback.lower().split(":")[0].split(".")[0].strip() in verdicts]
    assert repeated == []


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


def test_as_text_lists_the_questions_and_choices_without_marking_an_answer():
    text = make_quiz().as_text()
    assert text.splitlines() == [
        "Quiz: Chapter 01 <graph> (2 questions)",
        "Run this cell to answer: each click says whether you are right, and why. The answers are on "
        "the course website, under this chapter's quiz.",
        "1. Which process must run before ROS 2 nodes can find each other?",
        "   - roscore",
        "   - None: discovery is peer to peer",
        "2. What does a topic carry?",
        "   - Requests & replies",
        "   - Messages of one type",
        "   - Goals with feedback",
    ]


def test_as_html_shows_questions_and_choices_escaped_but_no_answer_and_no_feedback():
    quiz = make_quiz()
    page = quiz.as_html()
    assert "Chapter 01 &lt;graph&gt;" in page and "<graph>" not in page
    for question in quiz.questions:
        assert html.escape(question.prompt) in page
        for choice in question.choices:
            assert f"<li>{html.escape(choice.text)}</li>" in page  # every choice drawn alike
            assert html.escape(choice.feedback) not in page
    assert "&#10004;" not in page and "&#10008;" not in page and "answers are on the course website" in page


def test_answers_html_marks_the_correct_answers_with_every_feedback_escaped():
    quiz = make_quiz()
    page = quiz.answers_html()
    assert "Chapter 01 &lt;graph&gt;" in page and "<summary>Questions and answers</summary>" in page
    for question in quiz.questions:
        assert html.escape(question.prompt) in page
        for choice in question.choices:
            mark = "&#10004;" if choice.correct else "&#10008;"
            assert f"{mark} {html.escape(choice.text)}<br><small>{html.escape(choice.feedback)}" in page
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


def test_a_displayed_quiz_has_text_html_a_widget_and_its_name_in_the_metadata():
    from IPython.core.interactiveshell import InteractiveShell
    from IPython.utils.capture import capture_output

    InteractiveShell.instance()  # a shell to display into, as in a kernel
    quiz = Quiz.load("03_topics")
    with capture_output() as captured:
        quiz.show()
    (shown,) = captured.outputs
    assert shown.metadata == {"ros2_course": {"quiz": "03_topics"}}
    assert shown.data["text/plain"] == quiz.as_text() and shown.data["text/html"] == quiz.as_html()
    assert "application/vnd.jupyter.widget-view+json" in shown.data
    with capture_output() as captured:
        make_quiz().show()  # built in code: no file name to record
    assert not captured.outputs[0].metadata


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
    assert "passed (1/1 criteria)</b>" in good._repr_html_() and "Hint" not in good._repr_html_()
    assert "not passed yet (1/2 criteria)</b>" in page  # the count the text report has


def test_a_hint_shared_by_several_failed_cases_is_shown_once():
    report = CheckReport("Exercise 3.4")
    report.add("tilt of 10 degrees", False, "got 0.0", hint="atan2(y, x) is in radians")
    report.add("tilt of 45 degrees", False, "got 0.0", hint="atan2(y, x) is in radians")
    report.add("level", True, hint="atan2(y, x) is in radians")
    report.add("rate", False, hint="one message per sample")
    lines = report.summary().splitlines()
    assert [line.strip() for line in lines if "hint:" in line] == [
        "hint: atan2(y, x) is in radians", "hint: one message per sample"], lines
    assert lines.index("         hint: atan2(y, x) is in radians") == 2  # under the first case it explains
    page = report._repr_html_()
    assert page.count("Hint: atan2(y, x) is in radians") == 1 and page.count("Hint: one message") == 1


def test_pretty_printing_uses_the_summary():
    from IPython.lib.pretty import pretty

    report = CheckReport("Exercise")
    report.add("works", True)
    assert pretty(report) == report.summary()


def test_every_chapter_notebook_has_a_quiz_that_ran():
    """Each notebook (00 and every chapter, the lab 08b included) has a short quiz cell loading its own
    quiz file, and its saved output is what that file gives today: the quiz ran, with no error."""
    notebooks = sorted(glob.glob(os.path.join(os.path.dirname(__file__), "..", "notebooks", "*.ipynb")))
    assert len(notebooks) >= 12
    for path in notebooks:
        name = os.path.splitext(os.path.basename(path))[0]
        with open(path, encoding="utf-8") as handle:
            notebook = json.load(handle)
        cells = [c for c in notebook["cells"] if c["cell_type"] == "code" and "Quiz" in "".join(c["source"])]
        assert len(cells) == 1, f"{name} has {len(cells)} quiz cells, expected one"
        assert "".join(cells[0]["source"]).splitlines()[-1] == f'Quiz.load("{name}")', name
        outputs = cells[0].get("outputs", [])
        assert outputs and all(o["output_type"] != "error" for o in outputs), name
        (shown,) = [o for o in outputs if o.get("metadata", {}).get("ros2_course", {}).get("quiz") == name]
        quiz = Quiz.load(name)
        assert "".join(shown["data"]["text/plain"]) == quiz.as_text(), f"{name}: re-run its quiz cell"
        assert "".join(shown["data"]["text/html"]) == quiz.as_html(), f"{name}: re-run its quiz cell"
        saved = notebook["metadata"]["widgets"]["application/vnd.jupyter.widget-state+json"]["state"]
        assert shown["data"]["application/vnd.jupyter.widget-view+json"]["model_id"] in saved, name


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
