"""A working copy of the course notebooks for each student, updated without losing their edits.

Students edit and run their own copy of the notebooks, never the course's tracked files, so a
new version of the course (``git pull``, or an instructor updating the shared install) never
collides with their work. ``sync`` copies what is new and merges what changed, cell by cell:

* the version of each notebook as last copied is kept beside the copy (``.course-base/``), so
  every sync is a three-way merge: base = last copied, ours = the student's copy, theirs = the
  course's current notebook;
* cells the student changed stay as they are; cells the course added or changed arrive; cells
  the course removed go, unless the student had changed them;
* a cell both changed is a conflict: both versions are kept, the student's first, after a
  markdown note (tagged ``course-update-conflict``) that says what happened;
* outputs never conflict: a cell keeps the student's outputs unless its source came from the
  course, and then it carries the course's outputs;
* **saved or live, at a glance**: the course's outputs come from its reference run (another
  machine, another day). In the working copy each of them starts with a one-line note saying so,
  and its cell has no execution count (the prompt reads ``[ ]``). Running the cell replaces its
  outputs, note included, so an output without the note is always the student's own. A copy made
  before the notes existed gets them on its next sync, on the outputs that are still exactly the
  reference run's; outputs the student made are never touched;
* other files (``config/*.yaml``) are replaced if the student left them alone; otherwise the
  course's new version is written beside them as ``NAME.course-update``;
* a notebook the student deleted comes back fresh: deleting is how to start a chapter over.

Usage::

    python tools/working_copy.py                      # sync notebooks/ into ~/ros2-course-work
    python tools/working_copy.py --work DIR           # or into DIR (default: $ROS2_COURSE_WORK)
    python tools/working_copy.py --then jupyter lab   # sync, then run a program (the hub's way)

With ``--then`` the program runs even if the sync failed (the error is printed), so a student
always gets their server.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
COURSE_DIR = REPO / "notebooks"
WORK_ENV = "ROS2_COURSE_WORK"
DEFAULT_WORK = "~/ros2-course-work"
BASE_DIR = ".course-base"  # the course's files as last copied, beside the student's copy
CONFLICT_TAG = "course-update-conflict"
SKIPPED = {"conftest.py", "__pycache__", ".ipynb_checkpoints", BASE_DIR}
# Cell metadata that records how a cell was shown or run, not what it is.
VIEW_METADATA = {"collapsed", "scrolled", "jupyter", "execution", "ExecuteTime", "trusted"}
# The note in front of the outputs of the course's reference run (see the module docstring).
REFERENCE_KEY = "ros2_course"  # output metadata: {"ros2_course": {"reference_run": true}}
REFERENCE_NOTE = ("Saved output of the course's reference run, not yours: run this cell to see your "
                  "own (numbers, domains and times will differ).")


def work_dir(value: str | None = None) -> Path:
    """The student's working copy: ``value``, else ``$ROS2_COURSE_WORK``, else ~/ros2-course-work."""
    return Path(os.path.expanduser(value or os.environ.get(WORK_ENV) or DEFAULT_WORK))


# ---------------------------------------------------------------------- notebooks, cell by cell
def _text(source) -> str:
    return "".join(source) if isinstance(source, list) else source


def _content(cell: dict) -> tuple:
    """What a cell is (type, source, meaningful metadata), leaving out outputs and view state."""
    metadata = {k: v for k, v in cell.get("metadata", {}).items() if k not in VIEW_METADATA}
    return (cell.get("cell_type"), _text(cell.get("source", "")),
            json.dumps(metadata, sort_keys=True), json.dumps(cell.get("attachments"), sort_keys=True))


def _key(cell: dict):
    return cell.get("id") or ("no-id",) + _content(cell)


def _unique_id(wanted: str, taken: set[str]) -> str:
    candidate, number = wanted[:64], 2
    while candidate in taken:
        suffix = f"-{number}"
        candidate, number = wanted[:64 - len(suffix)] + suffix, number + 1
    taken.add(candidate)
    return candidate


def _note(cell_id: str, text: str) -> dict:
    return {"cell_type": "markdown", "id": cell_id, "metadata": {"tags": [CONFLICT_TAG]},
            "source": text}


CONFLICT_NOTE = ("**Course update: you and the course both changed the next cell.** Your version is "
                 "the first cell below, the course's new version the second. Keep the one you want "
                 "(or combine them), then delete the other one and this note.")
RETURNED_NOTE = ("**Course update: the course changed the next cell, which you had deleted.** Here "
                 "it is again; delete it and this note if you do not want it.")


def merge_cells(base: list[dict], ours: list[dict], theirs: list[dict]) -> tuple[list[dict], int]:
    """Three-way merge of cell lists by cell id; returns (cells, number of conflicts).

    The student's order is kept; a cell the course added goes after the cell it follows in the
    course's notebook.
    """
    base_by = {_key(c): c for c in base}
    theirs_by = {_key(c): c for c in theirs}
    ours_keys = {_key(c) for c in ours}
    taken = {c["id"] for c in ours + theirs if c.get("id")}
    groups: dict = {}  # key -> the cells that stand for it in the result, in order
    order: list = []
    conflicts = 0
    for cell in ours:
        key = _key(cell)
        if key in groups:  # a second cell with the same id: the student's own
            key = ("student", len(order))
            order.append(key)
            groups[key] = [cell]
            continue
        order.append(key)
        old, new = base_by.get(key), theirs_by.get(key)
        if new is None:  # the course removed it, or never had it
            keep = old is None or _content(cell) != _content(old)
            groups[key] = [cell] if keep else []
        elif _content(new) == _content(cell) or (old is not None and _content(new) == _content(old)):
            groups[key] = [cell]  # the course left it alone (or made the same change)
        elif old is not None and _content(cell) == _content(old):
            groups[key] = [copy.deepcopy(new)]  # only the course changed it: source and outputs
        else:
            conflicts += 1
            theirs_copy = copy.deepcopy(new)
            theirs_copy["id"] = _unique_id(f"{new.get('id', 'cell')}-course", taken)
            note = _note(_unique_id(f"{new.get('id', 'cell')}-conflict", taken), CONFLICT_NOTE)
            groups[key] = [note, cell, theirs_copy]
    for position, cell in enumerate(theirs):
        key = _key(cell)
        if key in ours_keys:
            continue
        old = base_by.get(key)
        if old is not None and _content(old) == _content(cell):
            continue  # the student deleted a cell the course did not change
        added = [copy.deepcopy(cell)]
        if old is not None:  # the student deleted it and the course changed it
            conflicts += 1
            added.insert(0, _note(_unique_id(f"{cell.get('id', 'cell')}-returned", taken),
                                  RETURNED_NOTE))
        before = [_key(c) for c in theirs[:position] if _key(c) in groups]
        at = order.index(before[-1]) + 1 if before else 0
        order.insert(at, key)
        groups[key] = added
    return [cell for key in order for cell in groups[key]], conflicts


def _merge_dict(base: dict, ours: dict, theirs: dict) -> dict:
    """Top-level three-way merge: a key the student left alone takes the course's value."""
    merged = dict(ours)
    for key in set(base) | set(theirs):
        if ours.get(key) == base.get(key):
            if key in theirs:
                merged[key] = theirs[key]
            else:
                merged.pop(key, None)
    return merged


def merge_notebooks(base: dict | None, ours: dict, theirs: dict) -> tuple[dict, int]:
    """Three-way merge of whole notebooks (JSON dicts); returns (notebook, conflicts)."""
    base = base or {"cells": [], "metadata": {}}
    cells, conflicts = merge_cells(base["cells"], ours["cells"], theirs["cells"])
    merged = dict(ours)
    merged["cells"] = cells
    merged["metadata"] = _merge_dict(base.get("metadata", {}), ours.get("metadata", {}),
                                     theirs.get("metadata", {}))
    merged["nbformat"] = max(ours.get("nbformat", 4), theirs.get("nbformat", 4))
    merged["nbformat_minor"] = max(ours.get("nbformat_minor", 0), theirs.get("nbformat_minor", 0))
    return merged, conflicts


# ---------------------------------------------------------------------- saved or live
def reference_marker() -> dict:
    """The output that goes first in the outputs of the reference run (markdown, and plain text)."""
    return {"output_type": "display_data", "metadata": {REFERENCE_KEY: {"reference_run": True}},
            "data": {"text/markdown": f"<small><i>{REFERENCE_NOTE}</i></small>",
                     "text/plain": REFERENCE_NOTE}}


def is_marked(cell: dict) -> bool:
    """True when the cell's outputs are the reference run's, with the note in front."""
    outputs = cell.get("outputs") or []
    return bool(outputs) and bool(outputs[0].get("metadata", {}).get(REFERENCE_KEY, {}).get("reference_run"))


def _mark(cell: dict) -> None:
    """Put the note in front of a code cell's outputs and take its execution counts away."""
    cell["execution_count"] = None
    outputs = [dict(output, execution_count=None) if output.get("output_type") == "execute_result"
               else output for output in cell.get("outputs") or []]
    cell["outputs"] = [reference_marker(), *outputs] if outputs else []


def student_edition(notebook: dict) -> dict:
    """The course notebook as a working copy receives it: every saved output marked as the reference run's."""
    edition = copy.deepcopy(notebook)
    for cell in edition.get("cells", []):
        if cell.get("cell_type") == "code" and not is_marked(cell):
            _mark(cell)
    return edition


def _run_record(cell: dict) -> str:
    """A code cell's execution count and outputs, in a form that does not depend on how they were saved."""
    def text(value):
        return "".join(value) if isinstance(value, list) else value

    outputs = []
    for output in cell.get("outputs") or []:
        output = {key: (text(value) if key == "text" else value) for key, value in output.items()}
        if "data" in output:
            output["data"] = {kind: text(value) for kind, value in output["data"].items()}
        outputs.append(output)
    return json.dumps([cell.get("execution_count"), outputs], sort_keys=True)


def mark_reference_outputs(notebook: dict, *references: dict | None) -> int:
    """Mark the outputs in ``notebook`` that are exactly a reference notebook's for the same cell.

    For working copies made before the notes existed: their cells still carry the reference run's
    outputs, unmarked. A cell whose count and outputs equal the course's (as last copied, or now)
    gets the note; a cell the student ran has another count or other outputs and stays as it is
    (a run that repeats the reference run to the byte, count included, cannot be told from it and
    is marked too: its note is then true of what it shows). Returns how many cells were marked.
    """
    records = {}
    for reference in references:
        for cell in (reference or {}).get("cells", []):
            if cell.get("cell_type") == "code" and cell.get("id"):
                records.setdefault(cell["id"], set()).add(_run_record(cell))
    marked = 0
    for cell in notebook.get("cells", []):
        ran = cell.get("outputs") or cell.get("execution_count") is not None
        if (cell.get("cell_type") == "code" and ran and not is_marked(cell)
                and _run_record(cell) in records.get(cell.get("id"), ())):
            marked += bool(cell.get("outputs"))  # a cell without outputs only loses its count
            _mark(cell)
    return marked


# ---------------------------------------------------------------------- files
def _read_json(path: Path) -> dict | None:
    try:
        with open(path, encoding="utf-8") as handle:
            return json.load(handle)
    except FileNotFoundError:
        return None


def _dumps(notebook: dict) -> bytes:
    return (json.dumps(notebook, indent=1, sort_keys=True, ensure_ascii=False) + "\n").encode()


def _write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (a reader never sees half a notebook)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(handle, "wb") as out:
            out.write(data)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def _read(path: Path) -> bytes | None:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        return None


def course_files(course: Path) -> list[Path]:
    """The files of the course to copy, relative to ``course`` (notebooks and their data)."""
    found = []
    for path in sorted(course.rglob("*")):
        relative = path.relative_to(course)
        if path.is_file() and not SKIPPED & set(relative.parts) and not relative.name.startswith("."):
            found.append(relative)
    return found


def sync_file(relative: Path, course: Path, work: Path) -> str:
    """Bring one course file into the working copy; return what happened, in a few words."""
    theirs = (course / relative).read_bytes()
    course_notebook = None
    if relative.suffix == ".ipynb":  # the copy receives the student edition (reference outputs marked)
        course_notebook = json.loads(theirs)
        theirs = _dumps(student_edition(course_notebook))
    target, base_path = work / relative, work / BASE_DIR / relative
    ours, base = _read(target), _read(base_path)
    if ours is None:
        _write(target, theirs)
        outcome = "copied"
    elif ours == theirs:
        outcome = "unchanged"
    elif relative.suffix == ".ipynb":
        base_notebook = json.loads(base) if base else None
        merged, conflicts = merge_notebooks(base_notebook, json.loads(ours), json.loads(theirs))
        marked = mark_reference_outputs(merged, base_notebook, course_notebook)
        data = _dumps(merged)
        if data != _dumps(json.loads(ours)):
            _write(target, data)
            outcome = f"merged, {conflicts} conflict(s) marked" if conflicts else "updated"
            if marked:
                outcome += f" ({marked} saved output(s) marked as the reference run's)"
        else:
            outcome = "kept your version" if base != theirs else "unchanged"
    elif base == ours:
        _write(target, theirs)
        outcome = "updated"
    elif base == theirs:
        outcome = "kept your version"
    else:
        _write(target.with_name(target.name + ".course-update"), theirs)
        outcome = f"kept your version; the course's new one is {relative.name}.course-update"
    if base != theirs:
        _write(base_path, theirs)
    return outcome


def sync(course: Path = COURSE_DIR, work: Path | None = None, echo=print) -> dict[str, str]:
    """Bring every course file into the student's working copy; return {file: what happened}."""
    work = work or work_dir()
    course = Path(course)
    if not (course / "00_welcome.ipynb").is_file():
        raise SystemExit(f"{course} does not hold the course notebooks (no 00_welcome.ipynb); "
                         "pass --course with the course's notebooks/ folder.")
    work.mkdir(parents=True, exist_ok=True)
    results = {}
    for relative in course_files(course):
        results[str(relative)] = outcome = sync_file(relative, course, work)
        if outcome != "unchanged":
            echo(f"{relative}: {outcome}")
    echo(f"working copy {work} is up to date with {course}")
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("command", nargs="?", choices=["sync"], default="sync")
    parser.add_argument("--course", default=str(COURSE_DIR), help="the course's notebooks/ folder")
    parser.add_argument("--work", default=None,
                        help=f"the working copy (default: ${WORK_ENV}, else {DEFAULT_WORK})")
    parser.add_argument("--then", nargs=argparse.REMAINDER, default=[],
                        help="a program (with its arguments) to run after syncing, in its place")
    args = parser.parse_args(argv)
    status = 0
    try:
        sync(Path(args.course), work_dir(args.work))
    except (OSError, ValueError, SystemExit) as exc:  # never keep a student from their server
        print(f"working copy not synced: {exc}", file=sys.stderr)
        status = 1
    if args.then:
        sys.stdout.flush()
        os.execvp(args.then[0], args.then)
    return status


if __name__ == "__main__":
    sys.exit(main())
