"""The student build of ``course_helpers`` (no ``solutions/``); proof that a release holds no solution.

:func:`build` copies the package without its reference solutions into a folder that goes on
``PYTHONPATH`` (students' servers, and every grading kernel, so a submission cannot import a
solution). :func:`check_imports` imports every checker from that folder in a fresh Python and
confirms ``course_helpers.solutions`` is missing there. :func:`find_solutions` looks for the
reference solutions' code lines in a folder (the release): a line counts when it is long
enough to be telling and appears nowhere in the course notebooks or the rest of the package.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

from tools.grading.source import NOTEBOOKS, REPO, SOLUTIONS

PACKAGE = REPO / "course_helpers"
MIN_LINE = 28  # characters: shorter lines (``return response``) say nothing about a solution


# Where the full course is installed in development mode (``pip install -e .``, the instructor's
# venv), setuptools' finder would still find ``course_helpers.solutions`` in the repository for a
# package imported from the student build. Python runs ``sitecustomize`` from ``PYTHONPATH`` at
# start-up: this one takes that finder out, so the build is all there is.
SITECUSTOMIZE = '''"""Student build of course_helpers: only this copy of the package may be imported."""
import sys

sys.meta_path[:] = [f for f in sys.meta_path
                    if not getattr(f, "__module__", "").startswith("__editable___course_helpers")]
'''


def build(dest: Path) -> Path:
    """Copy ``course_helpers`` without ``solutions/`` to ``dest/course_helpers`` and the interface
    packages to ``dest/interfaces``; return ``dest`` (the folder to put on ``PYTHONPATH``)."""
    target = dest / "course_helpers"
    if target.exists():
        shutil.rmtree(target)
    dest.mkdir(parents=True, exist_ok=True)
    shutil.copytree(PACKAGE, target, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "solutions"))
    # the interface packages live beside the package (core.build_interfaces.INTERFACES_DIR):
    # chapter 09 reads and builds them
    if (dest / "interfaces").exists():
        shutil.rmtree(dest / "interfaces")
    shutil.copytree(REPO / "interfaces", dest / "interfaces",
                    ignore=shutil.ignore_patterns("build", "install", "log"))
    (dest / "sitecustomize.py").write_text(SITECUSTOMIZE, encoding="utf-8")
    return dest


def check_imports(dest: Path) -> str:
    """Import every checker from the student build in a fresh Python; return what it printed.

    Raises ``RuntimeError`` if a checker fails to import, if the package comes from anywhere
    else, or if ``course_helpers.solutions`` can be imported.
    """
    from course_helpers.core import processes

    checkers = sorted(p.stem for p in (PACKAGE / "checks").glob("ch*.py"))
    code = (
        "import importlib, sys\n"
        "import course_helpers\n"
        f"assert course_helpers.__file__.startswith({str(dest)!r}), course_helpers.__file__\n"
        f"for name in {checkers!r}:\n"
        "    importlib.import_module('course_helpers.checks.' + name)\n"
        "try:\n"
        "    import course_helpers.solutions\n"
        "except ModuleNotFoundError:\n"
        "    print('course_helpers.solutions: absent')\n"
        "else:\n"
        "    raise SystemExit('course_helpers.solutions is importable from the student build')\n"
        f"print('checkers import without solutions:', len({checkers!r}))\n")
    code_, output = processes.run([sys.executable, "-c", code], env={"PYTHONPATH": str(dest)}, cwd=str(dest),
                                  timeout=120)
    if code_ != 0:
        raise RuntimeError(f"the student build of course_helpers does not work:\n{output}")
    return output


def _known_text() -> str:
    """Everything a student may see: the course notebooks' cells and the package without solutions."""
    parts = []
    for path in sorted(NOTEBOOKS.glob("*.ipynb")):
        for cell in json.loads(path.read_text(encoding="utf-8"))["cells"]:
            src = cell.get("source", "")
            parts.append("".join(src) if isinstance(src, list) else src)
    for path in sorted(PACKAGE.rglob("*.py")):
        if SOLUTIONS not in path.parents:
            parts.append(path.read_text(encoding="utf-8"))
    return "\n".join(parts)


def solution_lines() -> set[str]:
    """The telling code lines of the reference solutions (not comments, docstrings or imports)."""
    known = _known_text()
    lines = set()
    for path in sorted(SOLUTIONS.glob("ch*.py")):
        in_doc = False
        for raw in path.read_text(encoding="utf-8").splitlines():
            line = raw.strip()
            if line.count('"""') == 1:
                in_doc = not in_doc
                continue
            if in_doc or len(line) < MIN_LINE or line.startswith(("#", '"""', "import ", "from ")):
                continue
            if line not in known:
                lines.add(line)
    return lines


def _texts(root: Path):
    for path in sorted(root.rglob("*")):
        if not path.is_file() or "__pycache__" in path.parts:
            continue
        if path.suffix == ".ipynb":
            cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
            yield path, "\n".join("".join(c["source"]) if isinstance(c["source"], list) else c["source"]
                                  for c in cells)
        elif path.suffix in (".py", ".md", ".txt", ".yaml", ".json", ".html"):
            yield path, path.read_text(encoding="utf-8", errors="replace")


def find_solutions(root: Path) -> list[str]:
    """``file: line`` for every reference-solution line found under ``root`` (empty: none)."""
    secrets = solution_lines()
    found = []
    for path, text in _texts(root):
        for line in sorted(secrets):
            if line in text:
                found.append(f"{path.relative_to(root)}: {line}")
    return found
