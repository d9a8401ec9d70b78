"""Move each chapter's quiz out of its notebook into a quiz file, so no cell or output shows the answers.

For every notebook given (default: all of ``notebooks/*.ipynb``), in place:

1. its quiz cell, if it still builds the quiz in code (``Quiz('03 Topics', [Question(...), ...])``), is
   read (the ``Quiz(...)`` expression is evaluated, nothing else of the cell runs) and written to
   ``course_helpers/notebook/quizzes/<notebook name>.yaml``; a quiz file that already holds the same
   quiz is left as it is, one that differs is rewritten and reported (check it with ``git diff``);
2. the cell's source becomes ``from course_helpers.notebook.quiz import Quiz`` / ``Quiz.load("<name>")``;
3. that cell alone runs in a fresh kernel (the quiz needs no ROS), and its outputs and the widget
   models they show replace the cell's old outputs and the old quiz's widget models. No other cell is
   run or changed; the cell keeps its id and execution count.

A notebook whose quiz cell is already converted, with the outputs the quiz file gives today, is not
touched, so running the script again changes nothing. A converted cell whose quiz file was edited
since gets step 3 only (its saved outputs refreshed from the file). Usage::

    .venv/bin/python tools/move_quizzes_out_of_notebooks.py                    # every notebook
    .venv/bin/python tools/move_quizzes_out_of_notebooks.py notebooks/03_topics.ipynb

Merging this change into a branch whose notebooks still hold their quizzes in code (the other
branch's notebooks win, then this script converts them)::

    git merge quiz                                                 # notebooks changed on both sides conflict
    git checkout --ours -- notebooks/NN_x.ipynb ...                # keep this branch's version of each
    .venv/bin/python tools/move_quizzes_out_of_notebooks.py        # converts what needs it, no more
    git diff course_helpers/notebook/quizzes/                      # a quiz the branch changed shows here
    .venv/bin/python -m pytest tests/test_quiz_answers_hidden.py tests/test_quiz_and_checks.py -q
    git add notebooks course_helpers/notebook/quizzes && git commit

A notebook that merged without a conflict is checked too, and reported unchanged when its quiz cell
is current.

The rest of the notebook keeps its saved outputs, so it needs no re-execution: only the quiz cell's
output changed, and this script produced it. Strict nbval of the notebook should pass as it is.
"""

from __future__ import annotations

import ast
import copy
import json
import os
import re
import sys
from pathlib import Path

import nbformat
import yaml

from course_helpers.notebook.quiz import METADATA_KEY, QUIZ_DIR, Choice, Question, Quiz
from tools.execute_notebooks import run

REPO = Path(__file__).resolve().parent.parent
WIDGET_VIEW = "application/vnd.jupyter.widget-view+json"
WIDGET_STATE = "application/vnd.jupyter.widget-state+json"
MODEL_REF = re.compile(r"IPY_MODEL_([0-9a-f]{32})")
CELL_SOURCE = 'from course_helpers.notebook.quiz import Quiz\nQuiz.load("{name}")'


def quiz_cell(notebook, path: Path) -> nbformat.NotebookNode:
    """The notebook's one quiz cell (a code cell that builds or loads a Quiz)."""
    cells = [cell for cell in notebook.cells
             if cell.cell_type == "code" and re.search(r"\bQuiz(\.load)?\(", cell.source)]
    if len(cells) != 1:
        raise SystemExit(f"{path.name}: expected one quiz cell (a code cell with Quiz(...) or "
                         f"Quiz.load(...)), found {len(cells)}")
    return cells[0]


def quiz_in_code(source: str) -> Quiz | None:
    """The quiz an old-style cell builds with ``Quiz(title, [...])``, or None for a converted cell."""
    calls = [node for node in ast.walk(ast.parse(source))
             if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "Quiz"]
    if not calls:
        return None
    expression = ast.Expression(calls[0])
    try:
        return eval(compile(expression, "<quiz cell>", "eval"),  # noqa: S307 (the course's own cell)
                    {"Quiz": Quiz, "Question": Question, "Choice": Choice})
    except Exception as error:  # noqa: BLE001 (any mistake in the cell's Quiz(...) is reported the same way)
        raise SystemExit(f"the quiz cell's Quiz(...) cannot be read on its own ({type(error).__name__}: "
                         f"{error}); it may use only literal text, Quiz, Question and Choice") from None


class _IndentedLists(yaml.SafeDumper):
    """Indents list items under their key (``questions:\\n  - prompt: ...``), which reads better."""

    def increase_indent(self, flow=False, indentless=False):
        return super().increase_indent(flow, False)


def write_quiz_file(quiz: Quiz, name: str) -> str:
    """Write ``quizzes/<name>.yaml`` unless it already holds this quiz; return what happened."""
    path = QUIZ_DIR / f"{name}.yaml"
    if path.exists() and Quiz.from_file(path).to_dict() == quiz.to_dict():
        return f"{path.relative_to(REPO)} already holds this quiz"
    existed = path.exists()
    header = (f"# The quiz of notebooks/{name}.ipynb, shown by its quiz cell: Quiz.load(\"{name}\").\n"
              "# Mark each right choice with `correct: true`; the others are wrong.\n")
    body = yaml.dump(quiz.to_dict(), Dumper=_IndentedLists, sort_keys=False, allow_unicode=True, width=100)
    QUIZ_DIR.mkdir(exist_ok=True)
    path.write_text(header + body, encoding="utf-8")
    Quiz.load(name)  # what was written reads back (the validation runs on it)
    if existed:
        return (f"REWROTE {path.relative_to(REPO)}: the notebook's quiz differs from the file's "
                "(see git diff)")
    return f"wrote {path.relative_to(REPO)}"


def _is_current(cell, quiz: Quiz, notebook) -> bool:
    """True when the cell is converted and its outputs are what the quiz file gives today."""
    if cell.source != CELL_SOURCE.format(name=quiz.name) or len(cell.get("outputs", [])) != 1:
        return False
    output = cell.outputs[0]
    data = output.get("data", {})
    saved = notebook.metadata.get("widgets", {}).get(WIDGET_STATE, {}).get("state", {})
    return (output.output_type == "display_data"
            and output.get("metadata", {}).get(METADATA_KEY, {}).get("quiz") == quiz.name
            and data.get("text/plain") == quiz.as_text() and data.get("text/html") == quiz.as_html()
            and data.get(WIDGET_VIEW, {}).get("model_id") in saved)


def _models_shown(outputs) -> set[str]:
    return {o["data"][WIDGET_VIEW]["model_id"] for o in outputs if WIDGET_VIEW in o.get("data", {})}


def _reachable(roots: set[str], state: dict) -> set[str]:
    """Every widget model that ``roots`` refer to, directly or through other models."""
    seen, todo = set(), list(roots)
    while todo:
        model = todo.pop()
        if model in seen or model not in state:
            continue
        seen.add(model)
        todo += MODEL_REF.findall(json.dumps(state[model]))
    return seen


def run_quiz_cell(source: str, notebook, cwd: str) -> tuple[list, dict]:
    """Run ``source`` alone in a fresh kernel: (its outputs, the widget models they show)."""
    alone = nbformat.v4.new_notebook(metadata=copy.deepcopy({k: v for k, v in notebook.metadata.items()
                                                             if k in ("kernelspec", "language_info")}))
    alone.cells = [nbformat.v4.new_code_cell(source)]
    run(alone, cwd, timeout=120)
    outputs = alone.cells[0].outputs
    errors = [o for o in outputs if o.output_type == "error"]
    if errors:
        raise SystemExit(f"the quiz cell failed: {errors[0].ename}: {errors[0].evalue}")
    state = alone.metadata.get("widgets", {}).get(WIDGET_STATE, {}).get("state", {})
    return outputs, {model: state[model] for model in _reachable(_models_shown(outputs), state)}


def convert(path: Path) -> list[str]:
    """Convert one notebook in place; return what was done, one line each."""
    notebook = nbformat.read(path, as_version=4)
    name = path.stem
    cell = quiz_cell(notebook, path)
    done = []
    in_code = quiz_in_code(cell.source)
    if in_code is not None:
        done.append(write_quiz_file(in_code, name))
    elif not (QUIZ_DIR / f"{name}.yaml").exists():
        raise SystemExit(f"{path.name}: its quiz cell loads a quiz and there is no "
                         f"{(QUIZ_DIR / name).relative_to(REPO)}.yaml (was the notebook renamed? "
                         "rename its quiz file too)")
    quiz = Quiz.load(name)
    if _is_current(cell, quiz, notebook):
        return done + ["quiz cell already converted, outputs current: notebook unchanged"]

    source = CELL_SOURCE.format(name=name)
    outputs, new_models = run_quiz_cell(source, notebook, str(path.parent))
    widgets = notebook.metadata.setdefault("widgets", {}).setdefault(
        WIDGET_STATE, {"state": {}, "version_major": 2, "version_minor": 0})
    state = widgets["state"]
    others = set().union(*(_models_shown(c.get("outputs", [])) for c in notebook.cells
                           if c.cell_type == "code" and c is not cell))
    stale = _reachable(_models_shown(cell.get("outputs", [])), state) - _reachable(others, state)
    for model in stale:
        del state[model]
    state.update(new_models)
    what = "outputs refreshed from the quiz file" if cell.source == source else "converted"
    cell.source = source
    cell.outputs = outputs
    nbformat.validate(notebook)
    nbformat.write(notebook, path)
    return done + [f"quiz cell {what}, re-run alone ({len(stale)} old widget models replaced "
                   f"by {len(new_models)})"]


def main(paths: list[str]) -> int:
    notebooks = [Path(p).resolve() for p in paths] or sorted((REPO / "notebooks").glob("*.ipynb"))
    for path in notebooks:
        print(f"{os.path.relpath(path, REPO)}:", flush=True)
        for line in convert(path):
            print(f"  {line}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
