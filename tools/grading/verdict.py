"""Is an assignment graded right? The verdict of ``tools/assignments.py grade-all`` on one grade table.

``grade-all`` hands in two submissions of every released chapter and grades them together with
``grade``: the untouched starting code first (:data:`STARTING`), then the reference
(:data:`REFERENCE`, every exercise cell holding its reference solution). The grade table is right
when

* both were graded to the end: the starting code's run, whatever it did, did not stop the next one;
* the reference earns every point of every exercise;
* the starting code earns less than every point of every exercise (it solves none of them).

:func:`judge` turns a grade table into one :class:`Line` per exercise, each with the problems
found (empty when it is right); :func:`table` prints them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from tools.grading.results import StudentResult

STARTING = "1-starting-code"  # graded first: a wrong submission that must not stop the next student
REFERENCE = "2-reference"
TEST_SUFFIX = "_check"  # a test cell's grade id is its exercise's followed by this
REASON_CHARS = 70  # of the starting code's reason, in the printed table


@dataclass
class Line:
    """One exercise of one assignment: what the reference and the starting code scored, and what is wrong."""

    assignment: str
    exercise: str
    max_points: float
    reference: tuple[float, str] | None = None  # (points, reason); None: not graded
    starting: tuple[float, str] | None = None
    problems: list[str] = field(default_factory=list)


def _exercise(grade_id: str) -> str:
    return grade_id.removesuffix(TEST_SUFFIX)


def judge(assignment: str, max_points: dict[str, float], graded: list[StudentResult],
          starting: str = STARTING, reference: str = REFERENCE) -> list[Line]:
    """One line per exercise of ``assignment`` (``max_points``: test cell grade id -> its points), judged
    from the grade table's results of the students ``starting`` (the starting code) and ``reference``."""
    by_student = {r.student: r for r in graded}
    lines = [Line(assignment, _exercise(g), m) for g, m in max_points.items()]
    if not lines:
        return [Line(assignment, "-", 0, problems=[f"{assignment}: the assignment has no graded exercise"])]
    for is_reference, student in ((False, starting), (True, reference)):
        result = by_student.get(student)
        failure = "was not graded" if result is None else (
            f"was not graded to the end: {result.run_failure}" if result.run_failure else "")
        if failure:
            lines[0].problems.append(f"{assignment}: {student} {failure}")
        if result is None:
            continue
        for line, grade_id in zip(lines, max_points, strict=True):
            points, _, reason = result.grades[grade_id]
            if is_reference:
                line.reference = (points, reason)
                if points < line.max_points and not failure:
                    line.problems.append(f"{assignment}, {line.exercise}: the reference scored "
                                         f"{points:g}/{line.max_points:g} ({reason or 'no reason given'})")
            else:
                line.starting = (points, reason)
                if points >= line.max_points:
                    line.problems.append(f"{assignment}, {line.exercise}: the starting code was not marked "
                                         f"down ({points:g}/{line.max_points:g}): the checker accepts it")
    return lines


def problems(lines: list[Line]) -> list[str]:
    return [p for line in lines for p in line.problems]


def notes(assignment: str, graded: list[StudentResult]) -> list[str]:
    """What the grader noted about the runs (processes it had to kill, ...): worth a look, not a failure."""
    return [f"{assignment}, {r.student}: {note}" for r in graded for note in r.notes]


def _score(scored: tuple[float, str] | None, max_points: float) -> str:
    return "-" if scored is None else f"{scored[0]:g}/{max_points:g}"


def table(lines: list[Line]) -> str:
    """The lines as a Markdown table: the scores, why the starting code lost its points, the verdict."""
    head = ["assignment", "exercise", "reference", "starting code", "why the starting code lost points",
            "verdict"]
    rows = []
    for line in lines:
        why = (line.starting[1] if line.starting else "").replace("|", "/")
        if len(why) > REASON_CHARS:
            why = why[:REASON_CHARS - 3] + "..."
        rows.append([line.assignment, line.exercise, _score(line.reference, line.max_points),
                     _score(line.starting, line.max_points), why, "FAIL" if line.problems else "ok"])
    widths = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]
    out = ["| " + " | ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) + " |"
           for row in [head, ["-" * w for w in widths], *rows]]
    return "\n".join(out)
