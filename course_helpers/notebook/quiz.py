"""Multiple-choice quizzes with feedback on every answer (the closing section of every chapter).

Each chapter's quiz is a small YAML file in ``quizzes/`` beside this module, so the answers are in
neither the notebook's cells nor its saved outputs (nor a student's working copy of the notebooks).
A chapter's quiz cell is::

    from course_helpers.notebook.quiz import Quiz
    Quiz.load("03_topics")

In JupyterLab the quiz is a set of buttons: clicking an answer says whether it is right and why.
A saved notebook (nbval, GitHub, a kernel-less reader) shows the questions and their choices with
no answer marked. The course website shows the answers: ``tools/build_book.py`` puts
:meth:`Quiz.answers_html` in place of the saved record, under "Questions and answers".

A quiz file::

    title: 03 Topics
    questions:
      - prompt: Which command lists the active topics with their types?
        choices:
          - text: ros2 node list
            feedback: That lists nodes.
          - text: ros2 topic list -t
            correct: true
            feedback: "%ros2 topic list -t in this notebook."

A choice without ``correct: true`` is a wrong one. Quizzes can also be built in code:
``Quiz(title, [Question(prompt, [Choice(text, correct, feedback), ...]), ...])``.
"""

from __future__ import annotations

import html
from dataclasses import dataclass, field
from pathlib import Path

from course_helpers.core.errors import CourseError

QUIZ_DIR = Path(__file__).resolve().parent / "quizzes"
# Output metadata of a displayed quiz: {"ros2_course": {"quiz": "03_topics"}} (the site finds it so).
METADATA_KEY = "ros2_course"
# What a quiz file's entries hold: key -> kind of value; every key but "correct" is required.
FILE_KEYS = {"title": "text", "questions": "list"}
QUESTION_KEYS = {"prompt": "text", "choices": "list"}
CHOICE_KEYS = {"text": "text", "correct": "true or false", "feedback": "text"}
OPTIONAL_KEYS = {"correct"}


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
    """A titled list of questions; ``show()`` displays it, ``grade()`` scores picks in code.

    ``name`` is the quiz file it came from ("03_topics"), empty for a quiz built in code.
    """

    title: str
    questions: list[Question]
    name: str = ""
    picks: dict[int, int] = field(default_factory=dict, compare=False)

    def __post_init__(self):
        self.questions = list(self.questions)
        if not self.questions:
            raise CourseError(f"quiz {self.title!r} needs at least one question")
        for question in self.questions:
            if not isinstance(question, Question):
                raise CourseError(f"quiz {self.title!r}: each question must be "
                                  f"Question(prompt, [Choice(...), ...]), got {question!r}")

    # ------------------------------------------------------------------ files
    @classmethod
    def names(cls) -> list[str]:
        """The course's quizzes, by name (the file names in ``quizzes/`` without ``.yaml``)."""
        return sorted(path.stem for path in QUIZ_DIR.glob("*.yaml"))

    @classmethod
    def load(cls, name: str) -> Quiz:
        """The course's quiz ``name`` ("03_topics"), read from ``quizzes/<name>.yaml``."""
        if not isinstance(name, str) or name not in cls.names():
            raise CourseError(f"there is no quiz named {name!r}; the course's quizzes are "
                              f"{', '.join(cls.names()) or '(none)'}")
        return cls.from_file(QUIZ_DIR / f"{name}.yaml")

    @classmethod
    def from_file(cls, path: str | Path) -> Quiz:
        """A quiz read from the YAML file ``path``; a mistake raises CourseError naming the file and
        the question or choice at fault."""
        import yaml

        path = Path(path)
        try:
            data = yaml.safe_load(path.read_text(encoding="utf-8"))
        except OSError as error:
            raise CourseError(f"cannot read the quiz file {path}: {error.strerror}") from None
        except yaml.YAMLError as error:
            raise CourseError(f"{path.name} is not valid YAML: {error}") from None
        try:
            return cls.from_dict(data, name=path.stem)
        except CourseError as error:
            raise CourseError(f"{path.name}: {error}") from None

    @classmethod
    def from_dict(cls, data, name: str = "") -> Quiz:
        """A quiz from the mapping a quiz file holds (``title``, ``questions``)."""
        _check_entry(data, FILE_KEYS, "the file")
        questions = []
        for qi, entry in enumerate(data["questions"], 1):
            _check_entry(entry, QUESTION_KEYS, f"question {qi}")
            choices = []
            for ci, item in enumerate(entry["choices"], 1):
                _check_entry(item, CHOICE_KEYS, f"question {qi}, choice {ci}")
                choices.append(Choice(item["text"], item.get("correct", False), item["feedback"]))
            questions.append(Question(entry["prompt"], choices))
        return cls(data["title"], questions, name=name)

    def to_dict(self) -> dict:
        """The mapping a quiz file holds (the inverse of :meth:`from_dict`)."""
        def choice(c: Choice) -> dict:
            return {"text": c.text, **({"correct": True} if c.correct else {}), "feedback": c.feedback}

        return {"title": self.title,
                "questions": [{"prompt": q.prompt, "choices": [choice(c) for c in q.choices]}
                              for q in self.questions]}

    # ------------------------------------------------------------------ answering
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

    # ------------------------------------------------------------------ display
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
        """Display the quiz: interactive in JupyterLab, the questions without answers when saved."""
        from IPython.display import display

        display(self)

    def _ipython_display_(self):
        from IPython.display import display

        metadata = {METADATA_KEY: {"quiz": self.name}} if self.name else None
        display({"text/plain": self.as_text(), "text/html": self.as_html(), **self._widget_bundle()},
                raw=True, metadata=metadata)

    def _widget_bundle(self) -> dict:
        try:
            from course_helpers.notebook.widget_errors import owned

            view = owned(self.widget(), f"quiz {self.name or self.title}")  # its callbacks' errors: a line
            bundle = view._repr_mimebundle_()
            return {k: v for k, v in bundle.items() if "widget-view" in k}
        except Exception:  # no widget support: the static rendering is enough
            return {}

    def as_text(self) -> str:
        """Plain text: the questions and their choices, no answer marked (what a notebook saves)."""
        lines = [f"Quiz: {self.title} ({len(self.questions)} questions)", _WHERE_ANSWERS]
        for qi, question in enumerate(self.questions):
            lines.append(f"{qi + 1}. {question.prompt}")
            lines += [f"   - {choice.text}" for choice in question.choices]
        return "\n".join(lines)

    def as_html(self) -> str:
        """Static HTML: the questions and their choices, no answer marked (what a notebook saves)."""
        parts = [f"<div class='course-quiz'><h4>Quiz: {html.escape(self.title)}</h4>"
                 f"<p><i>{html.escape(_WHERE_ANSWERS)}</i></p><ol>"]
        for question in self.questions:
            parts.append(f"<li><b>{html.escape(question.prompt)}</b><ul>")
            parts += [f"<li>{html.escape(choice.text)}</li>" for choice in question.choices]
            parts.append("</ul></li>")
        parts.append("</ol></div>")
        return "".join(parts)

    def answers_html(self) -> str:
        """HTML for the course website: every question, the correct answers marked, all feedback,
        under "Questions and answers"."""
        parts = [f"<div class='course-quiz'><h4>Quiz: {html.escape(self.title)}</h4>",
                 "<p><i>Run the notebook to answer interactively. Reading this page? "
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


_WHERE_ANSWERS = ("Run this cell to answer: each click says whether you are right, and why. The answers "
                  "are on the course website, under this chapter's quiz.")


def _check_entry(entry, keys: dict[str, str], where: str) -> None:
    """Raise CourseError unless ``entry`` is a mapping with the ``keys`` (key -> kind of value)
    that are required, no other key, and a value of the right kind for each."""
    allowed = ", ".join(keys)
    if not isinstance(entry, dict):
        raise CourseError(f"{where} must be a mapping with the keys {allowed}, got {entry!r}")
    missing = [key for key in keys if key not in OPTIONAL_KEYS and key not in entry]
    unknown = sorted(str(key) for key in entry if key not in keys)
    if missing or unknown:
        problems = ([f"missing {', '.join(missing)}"] if missing else []) + \
                   ([f"unknown {', '.join(unknown)}"] if unknown else [])
        raise CourseError(f"{where}: {'; '.join(problems)} (the keys are {allowed})")
    for key, kind in keys.items():
        value = entry.get(key)
        fits = {"text": isinstance(value, str) and bool(value.strip()),
                "list": isinstance(value, list),
                "true or false": isinstance(value, bool)}[kind]
        if key in entry and not fits:
            raise CourseError(f"{where}: {key!r} must be {'non-empty ' * (kind == 'text')}{kind}, "
                              f"got {value!r}")


def _short(text: str, limit: int = 90) -> str:
    return text if len(text) <= limit else text[: limit - 1] + "…"
