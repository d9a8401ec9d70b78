"""No notebook shows a quiz's answers before the student answers (issue 22, "answers out of sight").

The answers live in the quiz files (``course_helpers/notebook/quizzes/*.yaml``), outside the
notebooks and outside a student's working copy. Nothing a notebook holds may tell which choice is
correct: not its code (``Choice('...', True, ...)``), not a saved output (a text or HTML record that
marks a choice or draws the correct one differently, or any choice's feedback), and not its saved
widget state (a quiz button saved as clicked, feedback already shown). The course website does show
the answers: ``tools/build_book.py`` puts them in its own copy of each notebook.
"""

from __future__ import annotations

import copy
import glob
import html
import json
import os
import re

import pytest

from course_helpers.notebook.quiz import Quiz
from tools import build_book

from .conftest import REPO

NOTEBOOKS = sorted(glob.glob(os.path.join(REPO, "notebooks", "*.ipynb")))
WIDGET_STATE = "application/vnd.jupyter.widget-state+json"
# What a rendering uses to mark an answer or to say how a pick went.
MARKS = ("[x]", "[X]", "&#10004;", "&#x2714;", "\u2714", "\u2713", "&#10008;", "\u2718",
         "Correct.", "Not quite.")


def _strings(value):
    """Every string inside a nested structure of dicts and lists (a saved output, a widget's state)."""
    if isinstance(value, str):
        yield value
    elif isinstance(value, dict):
        for item in value.values():
            yield from _strings(item)
    elif isinstance(value, list):
        joined = "".join(v for v in value if isinstance(v, str))  # a multi-line string saved as lines
        if joined:
            yield joined
        for item in value:
            if not isinstance(item, str):
                yield from _strings(item)


def _uneven_choices(text: str, quiz: Quiz, splitter: str, escape) -> list[str]:
    """Questions whose choices a record draws differently, apart from the choice's own text: the
    record shows the answer even without a mark. ``splitter`` cuts the record into the pieces that
    hold one choice each (lines of text, HTML elements)."""
    pieces = re.split(splitter, text)
    uneven, start = [], 0
    for number, question in enumerate(quiz.questions, 1):
        at = next((i for i in range(start, len(pieces)) if escape(question.prompt) in pieces[i]), None)
        if at is None:
            continue
        end = next((i for i in range(at + 1, len(pieces)) if number < len(quiz.questions)
                    and escape(quiz.questions[number].prompt) in pieces[i]), len(pieces))
        shapes = set()
        for choice in question.choices:
            holding = [p for p in pieces[at + 1:end] if escape(choice.text) in p]
            if holding:
                shapes.add(min(holding, key=len).replace(escape(choice.text), "<choice>", 1))
        if len(shapes) > 1:
            uneven.append(f"question {number} draws its choices differently: {sorted(shapes)}")
        start = end
    return uneven


def answer_leaks(notebook: dict, quiz: Quiz) -> list[str]:
    """Everything in ``notebook`` (a notebook's JSON) that shows an answer of ``quiz``, one line each."""
    leaks = []
    feedback = {c.feedback for q in quiz.questions for c in q.choices}

    def feedback_in(strings, where):
        found = {text for text in feedback for s in strings if text in s or html.escape(text) in s}
        return [f"{where} holds the feedback {text!r}" for text in sorted(found)]

    for index, cell in enumerate(notebook["cells"]):
        if cell["cell_type"] != "code":
            continue
        where = f"cell {index}"
        source = "".join(cell["source"])
        if re.search(r"\bChoice\s*\(", source):
            leaks.append(f"{where}: its code builds Choice(...), with the answers")
        leaks += feedback_in([source], f"{where}: its code")
        for output in cell.get("outputs", []):
            leaks += feedback_in(list(_strings(output)), f"{where}: an output")
            data = output.get("data", {})
            plain = "".join(data.get("text/plain", ""))
            if output.get("metadata", {}).get("ros2_course", {}).get("quiz") or plain.startswith("Quiz:"):
                record = "\n".join(_strings(data))
                leaks += [f"{where}: the quiz's record marks answers with {m!r}" for m in MARKS
                          if m in record]
                leaks += [f"{where}: text record: {u}" for u in _uneven_choices(plain, quiz, r"\n", str)]
                leaks += [f"{where}: HTML record: {u}" for u in _uneven_choices(
                    "".join(data.get("text/html", "")), quiz, r"(?=<li|</li|<br|<p)", html.escape)]
    state = notebook["metadata"].get("widgets", {}).get(WIDGET_STATE, {}).get("state", {})
    leaks += feedback_in(list(_strings(state)), "the saved widget state")
    leaks += [f"the saved widget state says {m!r}" for m in ("Correct.", "Not quite.")
              if any(m in s for s in _strings(state))]
    choices = {c.text for q in quiz.questions for c in q.choices}
    leaks += [f"the saved widget state has the quiz button {m['state']['tooltip']!r} clicked "
              f"({m['state']['button_style']})" for m in state.values()
              if m.get("model_name") == "ButtonModel" and m["state"].get("tooltip") in choices
              and m["state"].get("button_style")]
    return leaks


def _load(path: str) -> tuple[dict, Quiz]:
    with open(path, encoding="utf-8") as handle:
        notebook = json.load(handle)
    return notebook, Quiz.load(os.path.splitext(os.path.basename(path))[0])


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[os.path.basename(p) for p in NOTEBOOKS])
def test_no_notebook_shows_a_quiz_answer_in_its_code_outputs_or_widget_state(path):
    notebook, quiz = _load(path)
    assert not answer_leaks(notebook, quiz), "\n".join(answer_leaks(notebook, quiz))


def _quiz_output(notebook: dict) -> dict:
    return next(o for c in notebook["cells"] for o in c.get("outputs", [])
                if o.get("metadata", {}).get("ros2_course", {}).get("quiz"))


def test_the_leak_check_finds_each_way_an_answer_can_show():
    """Each bad example is one way a notebook could give an answer away; the check names every one."""
    notebook, quiz = _load(os.path.join(REPO, "notebooks", "03_topics.ipynb"))
    right = quiz.questions[0].choices[0]
    assert right.correct and right.text == "A topic"  # the examples below mark this one

    def leaks_after(change) -> str:
        bad = copy.deepcopy(notebook)
        change(bad)
        return "\n".join(answer_leaks(bad, quiz))

    def code_cell(source):
        return lambda nb: nb["cells"].append({"cell_type": "code", "source": source, "outputs": []})

    def quiz_data(key, value):
        return lambda nb: _quiz_output(nb)["data"].__setitem__(key, value)

    def widget(model_name, **state):
        return lambda nb: nb["metadata"]["widgets"][WIDGET_STATE]["state"].__setitem__(
            "f" * 32, {"model_name": model_name, "state": state})

    old_cell = "Question('?', [Choice('A topic', True, 'yes'), Choice('A service', False, 'no')])"
    assert "builds Choice" in leaks_after(code_cell(old_cell))
    assert "its code holds the feedback" in leaks_after(code_cell(f"print({right.feedback!r})"))
    marked = quiz.as_text().replace("   - A topic", "   [x] A topic")
    assert "marks answers with '[x]'" in leaks_after(quiz_data("text/plain", marked))
    assert "marks answers with '&#10004;'" in leaks_after(quiz_data("text/html", quiz.answers_html()))
    bold = quiz.as_html().replace("<li>A topic</li>", "<li><b>A topic</b></li>")
    assert "HTML record: question 1 draws its choices differently" in leaks_after(
        quiz_data("text/html", bold))
    starred = quiz.as_text().replace("   - A topic", "   * A topic")
    assert "text record: question 1 draws its choices differently" in leaks_after(
        quiz_data("text/plain", starred))
    printed = {"output_type": "stream", "name": "stdout", "text": [right.feedback + "\n"]}
    assert "an output holds the feedback" in leaks_after(
        lambda nb: next(c for c in nb["cells"] if c["cell_type"] == "code")["outputs"].append(printed))
    clicked = widget("ButtonModel", tooltip="A topic", button_style="success")
    assert "clicked (success)" in leaks_after(clicked)
    shown = f"<p>Correct. {html.escape(right.feedback)}</p>"
    assert "widget state holds the feedback" in leaks_after(widget("HTMLModel", value=shown))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[os.path.basename(p) for p in NOTEBOOKS])
def test_the_site_copy_of_each_notebook_shows_its_quiz_with_the_answers(path):
    """``make book`` stages each notebook with its quiz's answers (``tests/test_book_site.py`` checks
    the built pages in a browser); the committed notebook stays as it was."""
    notebook, quiz = _load(path)
    staged = copy.deepcopy(notebook)
    assert build_book.with_answers(staged) == [quiz.name]
    assert _quiz_output(staged)["data"]["text/html"] == quiz.answers_html()
    assert "application/vnd.jupyter.widget-view+json" not in _quiz_output(staged)["data"]
    assert [c for c in staged["cells"] if "Quiz" not in "".join(c["source"])] == \
        [c for c in notebook["cells"] if "Quiz" not in "".join(c["source"])]
