"""Multiple-choice quizzes with feedback on every answer (the closing section of every chapter).

In JupyterLab a quiz is a set of buttons: clicking an answer says whether it is
right and why. Rendered statically (a web page of the notebook, nbval), the same
quiz shows every question with its correct answer and the explanations, so
readers who cannot run the notebook still learn from it.

    from course_helpers.notebook.quiz import Quiz, Question, Choice
    Quiz("Chapter 01", [
        Question("Which process must start before ROS 2 nodes can find each other?", [
            Choice("roscore", False, "That was ROS 1's master; ROS 2 has none."),
            Choice("None: DDS discovery is peer to peer", True, "Right: ..."),
        ]),
    ]).show()
"""

from __future__ import annotations

import html
from dataclasses import dataclass, field

from course_helpers.core.errors import CourseError


@dataclass
class Choice:
    """One answer: its text, whether it is correct, and the feedback shown when picked."""

    text: str
    correct: bool
    feedback: str


@dataclass
class Question:
    """A question with two or more choices, at least one of them correct."""

    prompt: str
    choices: list[Choice]
    explanation: str = ""

    def __post_init__(self):
        self.choices = list(self.choices)
        for choice in self.choices:
            if not isinstance(choice, Choice):
                raise CourseError(f"question {self.prompt!r}: each choice must be "
                                  f"Choice(text, correct, feedback), got {choice!r}")
        if len(self.choices) < 2:
            raise CourseError(f"question {self.prompt!r} needs at least 2 choices")
        if not any(c.correct for c in self.choices):
            raise CourseError(f"question {self.prompt!r} has no correct choice")


@dataclass
class Quiz:
    """A titled list of questions; ``show()`` displays it, ``grade()`` scores picks in code."""

    title: str
    questions: list[Question]
    picks: dict[int, int] = field(default_factory=dict)

    def __post_init__(self):
        self.questions = list(self.questions)
        if not self.questions:
            raise CourseError(f"quiz {self.title!r} needs at least one question")
        for question in self.questions:
            if not isinstance(question, Question):
                raise CourseError(f"quiz {self.title!r}: each question must be "
                                  f"Question(prompt, [Choice(...), ...]), got {question!r}")

    def answer(self, question: int, choice: int) -> Choice:
        """Pick ``choice`` (0-based) for ``question`` (0-based); return it with its feedback."""
        if not 0 <= question < len(self.questions):
            raise CourseError(f"question must be 0..{len(self.questions) - 1}, got {question}")
        choices = self.questions[question].choices
        if not 0 <= choice < len(choices):
            raise CourseError(f"choice must be 0..{len(choices) - 1}, got {choice}")
        self.picks[question] = choice
        return choices[choice]

    def grade(self) -> tuple[int, int]:
        """(correct picks, number of questions)."""
        right = sum(self.questions[q].choices[c].correct for q, c in self.picks.items())
        return right, len(self.questions)

    def widget(self):
        """The interactive quiz as an ipywidgets VBox."""
        import ipywidgets as w

        score = w.HTML(self._score_html())
        rows = [w.HTML(f"<h4>{html.escape(self.title)}</h4>"), score]
        for qi, question in enumerate(self.questions):
            feedback = w.HTML()
            buttons = []
            for ci, choice in enumerate(question.choices):
                button = w.Button(description=_short(choice.text), tooltip=choice.text,
                                  layout=w.Layout(width="auto", max_width="100%"))
                button.on_click(self._on_pick(qi, ci, buttons, feedback, score))
                buttons.append(button)
            rows += [w.HTML(f"<b>{qi + 1}. {html.escape(question.prompt)}</b>"),
                     w.VBox(buttons), feedback]
        return w.VBox(rows)

    def show(self) -> None:
        """Display the quiz: interactive in JupyterLab, answers visible on a static page."""
        from IPython.display import display

        display(self)

    def _ipython_display_(self):
        from IPython.display import display

        display({"text/plain": self.as_text(),
                 "text/html": self.as_html(),
                 **self._widget_bundle()}, raw=True)

    def _widget_bundle(self) -> dict:
        try:
            view = self.widget()
            bundle = view._repr_mimebundle_()
            return {k: v for k, v in bundle.items() if "widget-view" in k}
        except Exception:  # no widget support: the static rendering is enough
            return {}

    def as_text(self) -> str:
        """Plain-text rendering with the answers (what nbval compares)."""
        lines = [f"Quiz: {self.title} ({len(self.questions)} questions)"]
        for qi, question in enumerate(self.questions):
            lines.append(f"{qi + 1}. {question.prompt}")
            for choice in question.choices:
                lines.append(f"   [{'x' if choice.correct else ' '}] {choice.text}")
        return "\n".join(lines)

    def as_html(self) -> str:
        """Static HTML rendering: every question, the correct answers marked, all feedback."""
        parts = [f"<div class='course-quiz'><h4>Quiz: {html.escape(self.title)}</h4>",
                 "<p><i>Run the notebook to answer interactively. Reading a static copy? "
                 "Open the answers below.</i></p><details><summary>Questions and answers"
                 "</summary><ol>"]
        for question in self.questions:
            parts.append(f"<li><b>{html.escape(question.prompt)}</b><ul>")
            for choice in question.choices:
                mark = "&#10004;" if choice.correct else "&#10008;"
                parts.append(f"<li>{mark} {html.escape(choice.text)}<br>"
                             f"<small>{html.escape(choice.feedback)}</small></li>")
            parts.append("</ul></li>")
        parts.append("</ol></details></div>")
        return "".join(parts)

    def _score_html(self) -> str:
        right, total = self.grade()
        return f"<i>Score: {right} / {total}</i>"

    def _on_pick(self, qi, ci, buttons, feedback, score):
        def handler(_button):
            choice = self.answer(qi, ci)
            for index, button in enumerate(buttons):
                button.button_style = ""
                if index == ci:
                    button.button_style = "success" if choice.correct else "danger"
            verdict = "Correct." if choice.correct else "Not quite."
            feedback.value = f"<p>{verdict} {html.escape(choice.feedback)}</p>"
            score.value = self._score_html()

        return handler


def _short(text: str, limit: int = 90) -> str:
    return text if len(text) <= limit else text[: limit - 1] + "…"
