"""The grade table: points per exercise from nbgrader's gradebook, a reason for every lost point.

Scores come from the gradebook nbgrader's autograde filled in. The reason for a lost point is
read from the autograded notebook: the errors in the exercise's solution or test cell
(``CellTimeoutError``, ``KernelDied``, ``OutputLimitExceeded``, ``RunawayProcesses``, an
exception of the student's code), otherwise the criteria the checker's report failed.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path

REASON_CHARS = 300
# Why a whole run has no grades: every exercise of the student then scores zero with this reason.
NOT_GRADED = "nbgrader could not grade it"
PAST_WALL_CLOCK = "grading took longer than the wall clock"
NO_GRADES = "nbgrader recorded no grades for this submission"


@dataclass
class StudentResult:
    """One student's grades: grade id -> (points, max points, reason), and notes on the run."""

    student: str
    grades: dict[str, tuple[float, float, str]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def total(self) -> float:
        return sum(points for points, _, _ in self.grades.values())

    @property
    def run_failure(self) -> str:
        """Why the run did not finish ('' if it did): then every exercise has that reason."""
        reasons = {reason for _, _, reason in self.grades.values()}
        if len(reasons) == 1:
            reason = reasons.pop()
            if reason.startswith((NOT_GRADED, PAST_WALL_CLOCK, NO_GRADES)):
                return reason
        return ""


def _text(cell: dict) -> str:
    src = cell.get("source", "")
    return "".join(src) if isinstance(src, list) else src


def _errors(cell: dict | None) -> list[str]:
    out = []
    for output in (cell or {}).get("outputs", []):
        if output.get("output_type") == "error":
            value = str(output.get("evalue", "")).strip().splitlines()
            out.append(f"{output.get('ename')}: {value[0]}" if value else str(output.get("ename")))
    return out


def _failed_criteria(cell: dict) -> list[str]:
    failed = []
    for output in cell.get("outputs", []):
        if output.get("output_type") == "stream":
            text = output.get("text", "")
            text = "".join(text) if isinstance(text, list) else text
            failed += [line.strip()[len("[FAIL] "):] for line in text.splitlines()
                       if line.strip().startswith("[FAIL]")]
    return failed


def reasons(notebook_path: Path) -> dict[str, str]:
    """grade id of each test cell -> why it lost points ('' if nothing is wrong that the notebook shows)."""
    nb = json.loads(notebook_path.read_text(encoding="utf-8"))
    by_id = {c["metadata"]["nbgrader"]["grade_id"]: c for c in nb["cells"]
             if c.get("metadata", {}).get("nbgrader", {}).get("grade_id")}
    found = {}
    for grade_id, cell in by_id.items():
        if not cell["metadata"]["nbgrader"].get("grade"):
            continue
        solution = by_id.get(grade_id.removesuffix("_check"))
        errors = [f"in the solution cell: {e}" for e in _errors(solution)] + _errors(cell)
        seen = list(dict.fromkeys(errors))
        if len(seen) > 1:  # an interrupt that a timeout or an output flood caused says nothing more
            seen = [e for e in seen if not e.endswith("KeyboardInterrupt")] or seen
        if seen:
            found[grade_id] = "; ".join(seen)[:REASON_CHARS]
        else:
            failed = _failed_criteria(cell)
            found[grade_id] = ("failed: " + "; ".join(failed))[:REASON_CHARS] if failed else ""
    return found


def collect(course_dir: Path, assignment: str, student: str, grade_ids: dict[str, float],
            failure: str = "") -> StudentResult:
    """The student's grades from the gradebook and the autograded notebook. ``grade_ids`` maps each
    test cell to its points; a ``failure`` (the run did not finish) gives zero everywhere with it."""
    from nbgrader.api import Gradebook, MissingEntry

    result = StudentResult(student)
    notebook = course_dir / "autograded" / student / assignment / f"{assignment}.ipynb"
    why = reasons(notebook) if notebook.exists() and not failure else {}
    scores: dict[str, float] = {}
    if not failure:
        with Gradebook(f"sqlite:///{course_dir / 'gradebook.db'}") as gb:
            try:
                submitted = gb.find_submission_notebook(assignment, assignment, student)
                scores = {g.name: float(g.score or 0.0) for g in submitted.grades}
            except MissingEntry:
                failure = NO_GRADES
    for grade_id, max_points in grade_ids.items():
        points = scores.get(grade_id, 0.0)
        reason = failure or why.get(grade_id, "")
        if points >= max_points:
            reason = ""
        elif not reason:
            reason = "not all criteria passed"
        result.grades[grade_id] = (points, max_points, reason)
    return result


def write_csv(path: Path, results: list[StudentResult], grade_ids: dict[str, float]) -> Path:
    """One row per student: points and reason per exercise, total, maximum, notes on the run."""
    path.parent.mkdir(parents=True, exist_ok=True)
    header = ["student"]
    for grade_id in grade_ids:
        header += [grade_id, f"{grade_id} reason"]
    header += ["total", "max", "seconds", "notes"]
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        for r in sorted(results, key=lambda r: r.student):
            row = [r.student]
            for grade_id in grade_ids:
                points, _, reason = r.grades[grade_id]
                row += [f"{points:g}", reason]
            row += [f"{r.total:g}", f"{sum(grade_ids.values()):g}", f"{r.seconds:.0f}", " | ".join(r.notes)]
            writer.writerow(row)
    return path


def read_csv(path: Path, grade_ids: dict[str, float]) -> list[StudentResult]:
    """The grade table :func:`write_csv` wrote, back as results; ``grade_ids`` maps each test cell
    to its points (the table holds the total maximum only). Raises ``ValueError`` if a column is missing."""
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    found = []
    for row in rows:
        missing = [g for g in grade_ids if g not in row or f"{g} reason" not in row]
        if missing:
            raise ValueError(f"{path} has no column for {missing}; it has {sorted(row)}")
        result = StudentResult(row["student"], seconds=float(row["seconds"]),
                               notes=[n for n in row["notes"].split(" | ") if n])
        for grade_id, max_points in grade_ids.items():
            result.grades[grade_id] = (float(row[grade_id]), max_points, row[f"{grade_id} reason"])
        found.append(result)
    return found
