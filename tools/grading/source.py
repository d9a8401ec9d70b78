"""The instructor source of a chapter's assignment, generated from the course notebook.

The course notebooks stay the single source. An exercise is found by its checker: a code
cell whose last statement calls ``check_...(...)`` imported from ``course_helpers.checks``,
right after the code cell that defines what the checker is given (a cell tagged
``exercise`` is taken as the exercise cell even when it is not right before). In the
generated notebook

* the exercise cell becomes an nbgrader solution cell: the student's starting code first,
  then the reference solution from ``course_helpers/solutions/<checker module>.py`` between
  ``### BEGIN SOLUTION`` and ``### END SOLUTION`` (what the release removes);
* an exercise of files (a checker called as ``check_x(read_package(folder))``: the student's answer
  is the files that ``%%writefile`` cells wrote into ``folder``) gets a solution cell of its own
  right before the checker cell: empty in the release, and in the instructor source the reference
  files written over the student's (with the ``write_package_files`` of ``read_package``'s module);
* the checker cell becomes a locked, autograded test cell worth one point per criterion the
  reference solution passes. It prints the report and ends with the score, a number nbgrader
  reads as partial credit; only a fully passed report earns every point;
* cells that import the reference solutions, show them (``show_solution``) or run the checker on
  them (``show_passing_report``) are left out,
  with a short markdown cell right before that introduces them ("compare with the solution").
"""

from __future__ import annotations

import ast
import copy
import json
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
NOTEBOOKS = REPO / "notebooks"
SOLUTIONS = REPO / "course_helpers" / "solutions"
CHECKS_PACKAGE = "course_helpers.checks."
SOLUTIONS_PACKAGE = "course_helpers.solutions"
BEGIN, END = "### BEGIN SOLUTION", "### END SOLUTION"
REPORT = "grade_report"
SCHEMA_VERSION = 3
FILES_READER, FILES_WRITER = "read_package", "write_package_files"  # an exercise of files (see above)
FILES_SKELETON = ("# Exercise: your answer is the files that the %%writefile cells above wrote into\n"
                  "# {folder}. Leave this cell as it is.\n")


@dataclass
class Exercise:
    """One exercise of a chapter: its cells, checker and reference solution."""

    grade_id: str
    code_index: int
    check_index: int
    checker: str
    module: str  # e.g. 'ch04_services': checks/<module>.py and solutions/<module>.py
    names: list[str]
    solution: str | None = None
    skipped: str = ""  # why the exercise is not graded (no reference solution, ...)
    files_reader: str = ""  # an exercise of files: the module of read_package (its answer: the folder)


@dataclass
class Chapter:
    """A chapter notebook turned into an assignment."""

    name: str
    notebook: dict
    exercises: list[Exercise] = field(default_factory=list)
    dropped: list[int] = field(default_factory=list)

    @property
    def graded(self) -> list[Exercise]:
        return [e for e in self.exercises if not e.skipped]


def _source(cell: dict) -> str:
    src = cell.get("source", "")
    return "".join(src) if isinstance(src, list) else src


def _parse(code: str) -> ast.Module | None:
    """The cell's syntax tree (IPython magics and shell lines blanked), or None if it is not Python."""
    lines = ["" if line.lstrip().startswith(("%", "!")) else line for line in code.splitlines()]
    try:
        return ast.parse("\n".join(lines))
    except SyntaxError:
        return None


def _defined(tree: ast.Module) -> set[str]:
    """Names a cell defines at its top level (classes, functions, assignments)."""
    names: set[str] = set()
    for node in tree.body:
        if isinstance(node, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for target in targets:
                names.update(n.id for n in ast.walk(target) if isinstance(n, ast.Name))
    return names


def _checker_imports(tree: ast.Module) -> dict[str, str]:
    """``check_x`` -> checker module name, for each checker a cell imports."""
    found = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(CHECKS_PACKAGE):
            for alias in node.names:
                if alias.name.startswith("check_"):
                    found[alias.asname or alias.name] = node.module[len(CHECKS_PACKAGE):]
    return found


def _shows_solutions(code: str, tree: ast.Module | None, solution_aliases: set[str]) -> bool:
    if SOLUTIONS_PACKAGE in code or "show_solution(" in code or "show_passing_report(" in code:
        return True
    if tree is None:
        return False
    return any(isinstance(n, ast.Name) and n.id in solution_aliases for n in ast.walk(tree))


def _solution_aliases(tree: ast.Module) -> set[str]:
    """Names a cell binds to the reference solutions (``from course_helpers.solutions import x as ref``)."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(SOLUTIONS_PACKAGE):
            names.update(a.asname or a.name for a in node.names)
        elif isinstance(node, ast.Import):
            names.update(a.asname or a.name.split(".")[0] for a in node.names
                         if a.name.startswith(SOLUTIONS_PACKAGE))
    return names


def find_exercises(name: str, notebook: dict) -> Chapter:
    """The exercises of a chapter notebook, and the cells that show reference solutions."""
    chapter = Chapter(name, notebook)
    cells = notebook["cells"]
    checkers: dict[str, str] = {}
    aliases: set[str] = set()
    trees = [(_parse(_source(c)) if c["cell_type"] == "code" else None) for c in cells]
    for i, (cell, tree) in enumerate(zip(cells, trees, strict=True)):
        if cell["cell_type"] != "code" or tree is None:
            continue
        checkers.update(_checker_imports(tree))
        aliases |= _solution_aliases(tree)
        if _shows_solutions(_source(cell), tree, aliases):
            chapter.dropped.append(i)
            before = cells[i - 1] if i > 0 else {}
            text = _source(before) if before.get("cell_type") == "markdown" else ""
            if "solution" in text.lower() and len(text) < 300:  # a short lead-in to the solution
                chapter.dropped.append(i - 1)
            continue
        last = tree.body[-1] if tree.body else None
        if not (isinstance(last, ast.Expr) and isinstance(last.value, ast.Call)
                and isinstance(last.value.func, ast.Name) and last.value.func.id in checkers):
            continue
        call = last.value
        folder, reader = _files_folder(call, tree)
        if folder:
            chapter.exercises.append(Exercise(f"ex{len(chapter.exercises) + 1}_{folder}", i, i, call.func.id,
                                              checkers[call.func.id], [folder], files_reader=reader))
            continue
        passed = [a.id for a in [*call.args, *(k.value for k in call.keywords)] if isinstance(a, ast.Name)]
        code_index = _exercise_cell(cells, trees, i, passed)
        if code_index is None:
            continue
        names = [n for n in passed if n in _defined(trees[code_index])]
        if set(names) & _defined(tree):
            continue  # the cell redefines what it checks: a worked example, not the exercise
        exercise = Exercise(f"ex{len(chapter.exercises) + 1}_{names[0]}", code_index, i, call.func.id,
                            checkers[call.func.id], names)
        exercise.solution, exercise.skipped = solution_code(exercise.module, names)
        if exercise.solution:
            # a value the student assigns (burst_qos = QoSProfile(...)) whose reference is a function
            # of the same name: the reference value is what that function returns
            assigned = [n for n in trees[code_index].body if isinstance(n, (ast.Assign, ast.AnnAssign))]
            values = _defined(ast.Module(body=assigned, type_ignores=[]))
            for name in names:
                if name in values and f"def {name}(" in exercise.solution:
                    exercise.solution += f"\n\n{name} = {name}()\n"
        chapter.exercises.append(exercise)
    for exercise in chapter.exercises:
        if exercise.files_reader:
            _files_from_function(exercise, cells)
        elif exercise.skipped and len(exercise.names) == 1:
            _value_from_function(exercise, cells)
    return chapter


def _files_folder(call: ast.Call, tree: ast.Module) -> tuple[str, str]:
    """``(folder, module of read_package)`` when the checker is called as ``check_x(read_package(folder))``
    in a cell that imports ``read_package``; else ``("", "")``."""
    if len(call.args) != 1 or call.keywords or not isinstance(call.args[0], ast.Call):
        return "", ""
    inner = call.args[0]
    if not (isinstance(inner.func, ast.Name) and inner.func.id == FILES_READER and len(inner.args) == 1
            and isinstance(inner.args[0], ast.Name)):
        return "", ""
    modules = [node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
               and any(alias.name == FILES_READER and not alias.asname for alias in node.names)]
    return (inner.args[0].id, modules[0]) if modules else ("", "")


def _files_from_function(exercise: Exercise, cells: list[dict]) -> None:
    """An exercise of files: its reference is a function of the solutions module that returns them
    (relative path -> text), named by the notebook's ``show_solution('chNN_x', 'function')``."""
    exercise.skipped = (f"no reference: the chapter shows no show_solution('{exercise.module}', ...) "
                        "that returns the package's files")
    for cell in cells[exercise.check_index + 1:]:
        for module, name in re.findall(r"show_solution\(\s*['\"](\w+)['\"]\s*,\s*['\"](\w+)['\"]",
                                       _source(cell)):
            code, _ = solution_code(module, [name]) if module == exercise.module else (None, "")
            if code is not None and f"def {name}(" in code:
                exercise.solution = (f"{code}\n\nfrom {exercise.files_reader} import {FILES_WRITER}\n\n"
                                     f"{FILES_WRITER}({exercise.names[0]}, {name}())\n")
                exercise.skipped = ""
                return


def _value_from_function(exercise: Exercise, cells: list[dict]) -> None:
    """An exercise whose answer is a value (``profiles = {...}``) whose reference is a function of
    the solutions module, named by the notebook's ``show_solution('chNN_x', 'function')``."""
    for cell in cells[exercise.check_index + 1:]:
        for module, name in re.findall(r"show_solution\(\s*['\"](\w+)['\"]\s*,\s*['\"](\w+)['\"]",
                                       _source(cell)):
            if module != exercise.module:
                continue
            code, _ = solution_code(module, [name])
            if code is not None and f"def {name}(" in code:
                exercise.solution = f"{code}\n\n{exercise.names[0]} = {name}()\n"
                exercise.skipped = ""
                return


def _exercise_cell(cells, trees, check_index: int, passed: list[str]) -> int | None:
    """The exercise cell a checker call belongs to: the tagged one, else the code cell right before."""
    for j in range(check_index - 1, -1, -1):
        if "exercise" in cells[j].get("metadata", {}).get("tags", []):
            return j if trees[j] is not None and set(passed) & _defined(trees[j]) else None
        if cells[j]["cell_type"] == "code":
            break
    j = check_index - 1
    if j >= 0 and trees[j] is not None and set(passed) & _defined(trees[j]):
        return j
    return None


# ---------------------------------------------------------------------- reference solutions
def solution_code(module: str, names: list[str]) -> tuple[str | None, str]:
    """``(code, "")``: the reference definitions of ``names`` with what they use from their module
    (imports, constants, helper functions), in file order; ``(None, reason)`` if there is none."""
    path = SOLUTIONS / f"{module}.py"
    if not path.exists():
        return None, f"no reference solution (course_helpers/solutions/{module}.py does not exist)"
    text = path.read_text(encoding="utf-8")
    tree = ast.parse(text)
    defs: dict[str, ast.stmt] = {}
    imports: dict[str, ast.stmt] = {}
    for node in tree.body:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            if isinstance(node, ast.ImportFrom) and node.module == "__future__":
                continue
            for alias in node.names:
                imports[alias.asname or alias.name.split(".")[0]] = node
        else:
            bound = _defined(ast.Module(body=[node], type_ignores=[]))
            for name in bound:
                defs[name] = node
    missing = [n for n in names if n not in defs]
    if missing:
        return None, f"course_helpers/solutions/{module}.py defines no {', '.join(missing)}"
    wanted: list[ast.stmt] = []
    todo = [defs[n] for n in names]
    while todo:
        node = todo.pop()
        if any(node is w for w in wanted):
            continue
        wanted.append(node)
        used = {n.id for n in ast.walk(node) if isinstance(n, ast.Name)}
        todo.extend(d for u, d in defs.items() if u in used and d is not node)
        todo.extend(d for u, d in imports.items() if u in used)
    ordered = [n for n in tree.body if any(n is w for w in wanted)]
    parts = [ast.get_source_segment(text, n, padded=False) for n in ordered]
    code = ""
    for node, part in zip(ordered, parts, strict=True):
        gap = "\n" if isinstance(node, (ast.Import, ast.ImportFrom)) else "\n\n\n"
        code += (gap if code else "") + part
    return code.replace("\n\n\n\n", "\n\n\n").strip() + "\n", ""


# ---------------------------------------------------------------------- the source notebook
def solution_cell(skeleton: str, solution: str) -> str:
    """The student's starting code, then the reference solution as nbgrader's solution region."""
    return f"{skeleton.rstrip()}\n{BEGIN}\n{solution.rstrip()}\n{END}"


def test_cell(check_source: str, points: int) -> str:
    """The checker cell made an autograded test: the checker's call kept, the report printed,
    and the score (points per passed criterion) as the cell's value."""
    tree = _parse(check_source)
    call = tree.body[-1]
    lines = check_source.splitlines()
    head = "\n".join(lines[:call.lineno - 1]).rstrip()
    call_text = ast.get_source_segment(check_source, call.value)
    body = (f"import contextlib\nimport sys\n\n"
            f"{head}\n\n"
            f"# Autograded: one point per criterion the reference solution passes ({points} in all);\n"
            f"# full points only when every criterion passes. A warning printed on stderr is not a failure.\n"
            f"with contextlib.redirect_stderr(sys.stdout):\n"
            f"    {REPORT} = {call_text}\n"
            f"print({REPORT}.summary())\n"
            f"POINTS = {points}\n"
            f"float(POINTS) if {REPORT}.passed else float(min(sum(c.passed for c in {REPORT}.criteria), "
            f"POINTS - 1))\n")
    return re.sub(r"\n{3,}", "\n\n", body)


def _nbgrader(grade_id: str, *, solution: bool, grade: bool, points: int | None = None) -> dict:
    meta = {"grade": grade, "grade_id": grade_id, "locked": grade, "schema_version": SCHEMA_VERSION,
            "solution": solution, "task": False}
    if points is not None:
        meta["points"] = points
    return meta


def build_source(chapter: Chapter, points: dict[str, int] | None = None) -> dict:
    """The instructor source notebook of ``chapter``; ``points`` maps grade ids of the test cells
    to their points (one per criterion, measured by running the reference, see ``release``)."""
    points = points or {}
    nb = copy.deepcopy(chapter.notebook)
    cells = nb["cells"]
    answers: dict[int, dict] = {}  # check cell index -> the solution cell of an exercise of files (before it)
    for exercise in chapter.graded:
        check = cells[exercise.check_index]
        if exercise.files_reader:
            answers[exercise.check_index] = code = {
                "cell_type": "code", "execution_count": None, "id": f"{exercise.grade_id}-answer",
                "metadata": {}, "outputs": [],
                "source": FILES_SKELETON.format(folder=exercise.names[0])}
        else:
            code = cells[exercise.code_index]
        code["source"] = solution_cell(_source(code), exercise.solution)
        code["outputs"], code["execution_count"] = [], None
        code.setdefault("metadata", {})["nbgrader"] = _nbgrader(exercise.grade_id, solution=True, grade=False)
        n = points.get(exercise.grade_id + "_check", 1)
        check["source"] = test_cell(_source(check), n)
        check["outputs"], check["execution_count"] = [], None
        check.setdefault("metadata", {})["nbgrader"] = _nbgrader(exercise.grade_id + "_check", solution=False,
                                                                 grade=True, points=n)
    nb["cells"] = [c for i, cell in enumerate(cells) if i not in set(chapter.dropped)
                   for c in ([answers[i]] if i in answers else []) + [cell]]
    for cell in nb["cells"]:
        if cell["cell_type"] == "code":
            cell["outputs"], cell["execution_count"] = [], None
    return nb


def load_chapter(notebook_path: Path) -> Chapter:
    with open(notebook_path, encoding="utf-8") as f:
        notebook = json.load(f)
    return find_exercises(notebook_path.stem, notebook)


def write_source(chapter: Chapter, course_dir: Path, points: dict[str, int] | None = None) -> Path:
    """Write ``source/<chapter>/<chapter>.ipynb`` (and the chapter's data files) under ``course_dir``."""
    folder = course_dir / "source" / chapter.name
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    nb = build_source(chapter, points)
    path = folder / f"{chapter.name}.ipynb"
    with open(path, "w", encoding="utf-8") as f:
        json.dump(nb, f, indent=1, ensure_ascii=False)
        f.write("\n")
    text = json.dumps(chapter.notebook)
    if "config/" in text and (NOTEBOOKS / "config").is_dir():
        shutil.copytree(NOTEBOOKS / "config", folder / "config")
    return path


def chapter_notebooks(selection: list[str] | None = None) -> list[Path]:
    """The chapter notebooks (``NN_*.ipynb``), all of them or those whose name starts with a selection."""
    found = sorted(p for p in NOTEBOOKS.glob("[0-9][0-9]*_*.ipynb"))
    if not selection:
        return found
    chosen = [p for p in found if any(p.stem.startswith(s) for s in selection)]
    if not chosen:
        raise SystemExit(f"no chapter notebook matches {selection}; there are {[p.stem for p in found]}")
    return chosen
