"""Graded assignments with nbgrader: the instructor source, the student release, autograding.

Usage (from the repository root, with the course's venv)::

    python tools/assignments.py source  [CHAPTER ...]     # assignments/source/<chapter>/ only
    python tools/assignments.py release [CHAPTER ...]     # source, validated, then the release
    python tools/assignments.py grade SUBMISSIONS --assignment 04_services
    python tools/assignments.py grade-all [CHAPTER ...]   # maintainers: release, grade, check

CHAPTER is a prefix of a notebook's name (``04`` or ``04_services``); no chapter means every
chapter with a graded exercise. ``release`` runs the instructor source once with the student
build (each reference solution must pass its checker: the points of a test cell are the
number of criteria it passed), runs nbgrader's own ``generate_assignment``, builds
``course_helpers`` without ``solutions/`` into ``assignments/student_build`` and checks that the
checkers import there and that no reference solution reached the release.

``grade`` takes a folder with one folder per student, holding ``<assignment>/<assignment>.ipynb``
(nbgrader's submitted layout) or ``<assignment>.ipynb``. Each submission is autograded by
nbgrader in a process of its own with a fresh kernel, its own ROS domain and temporary folder,
a timeout per cell and a wall clock for the whole run (:mod:`tools.grading.isolation`,
:mod:`tools.grading.guarded`); what it leaves running is killed and noted. It writes
``graded/<assignment>/grades.csv`` (points and the reason for every lost point),
``feedback/<student>.html`` (nbgrader's feedback) and ``log.json`` under the course directory.

``grade-all`` proves the whole chain on every chapter (in ``build/grade-all``): it releases them, hands
in each one's untouched starting code and its reference (:mod:`tools.grading.handin`), grades both with
``grade`` and checks the table (:mod:`tools.grading.verdict`): the reference earns every point, the starting
code less on every exercise. Exit status 1, naming the chapter and exercise, when it does not.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

from course_helpers.core.verdict import TimingVerdictError
from tools.grading import handin, isolation, results, source, student_build, verdict

COURSE_DIR = source.REPO / "assignments"
GRADE_ALL_DIR = source.REPO / "build" / "grade-all"  # generated, not committed
# nbgrader runs the venv's `alembic` for its gradebook: the venv's bin/ must be on PATH even
# when this script is run as .venv/bin/python without activating the venv.
os.environ["PATH"] = os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", "")
AUTOGRADE_ONE = Path(__file__).resolve().parent / "grading" / "autograde_one.py"
PROGRESS_EVERY_S = 15  # a line at least this often while a submission is graded
SUMMARY_PREFIX = ": "  # CheckReport.summary(): "<exercise>: PASSED (k/n criteria)"


def _api(course_dir: Path):
    from nbgrader.apps import NbGraderAPI

    from tools.grading.autograde_one import grading_config

    return NbGraderAPI(config=grading_config(str(course_dir)))


# ---------------------------------------------------------------------- source and release
def make_sources(chapters: list[str] | None, course_dir: Path, points: dict | None = None) -> list:
    """Write the instructor source of every chosen chapter that has a graded exercise."""
    made = []
    for path in source.chapter_notebooks(chapters):
        chapter = source.load_chapter(path)
        for exercise in chapter.exercises:
            if exercise.skipped:
                print(f"{chapter.name}: {exercise.grade_id} is not graded: {exercise.skipped}")
        if not chapter.graded:
            continue
        source.write_source(chapter, course_dir, (points or {}).get(chapter.name))
        made.append(chapter)
        print(f"{chapter.name}: {len(chapter.graded)} graded exercise(s) -> "
              f"{course_dir / 'source' / chapter.name}")
    return made


def _criteria(cell) -> tuple[int, int] | None:
    """(passed, total) from the report a test cell printed (``... (k/n criteria)``)."""
    for output in cell.get("outputs", []):
        if output.get("output_type") == "stream" and "criteria)" in output.get("text", ""):
            first = output["text"].split("criteria)")[0].rsplit("(", 1)[-1]
            passed, total = first.split("/")
            return int(passed), int(total)
    return None


def lesson_cell_problem(index: int, cell: dict) -> tuple[str | None, str | None]:
    """(why a lesson cell, one outside the exercises, keeps the chapter from being released, or None;
    a note to print, or None).

    The notebook must run as cleanly as the course's: a cell left out of the assignment must not have
    defined something a later cell needs. A lesson's timing claim that did not pass says nothing about
    that (it failed, or the machine was too busy to judge it; nbval judges those claims): it is
    printed as a note instead."""
    errors = [o for o in cell.get("outputs", []) if o.get("output_type") == "error"]
    if not errors or "raises-exception" in cell.get("metadata", {}).get("tags", []):
        return None, None
    first = errors[0]
    if first["ename"] == TimingVerdictError.__name__:
        return None, f"note: cell {index}'s timing claim did not pass (not part of the assignment): " \
                     f"{first['evalue']}"[:400]
    return f"cell {index} raised {first['ename']}: {first['evalue']}"[:300], None


def validate(chapter, course_dir: Path, build: Path, timeout: int) -> dict[str, int]:
    """Run the instructor source in a fresh kernel with the student build; return the points of
    each test cell (the criteria its reference solution passed). Raises if a reference fails."""
    import nbformat
    from nbclient import NotebookClient

    from tools.kernels import AsyncPrivateSocketKernelManager

    folder = course_dir / "source" / chapter.name
    nb = nbformat.read(folder / f"{chapter.name}.ipynb", as_version=4)
    saved = {k: os.environ.get(k) for k in ("PYTHONPATH", "ROS_DOMAIN_ID")}
    os.environ["PYTHONPATH"] = str(build)
    os.environ.pop("ROS_DOMAIN_ID", None)
    try:
        NotebookClient(nb, timeout=timeout, allow_errors=True, kernel_name="python3",
                       kernel_manager_class=AsyncPrivateSocketKernelManager,  # no port to collide on
                       resources={"metadata": {"path": str(folder)}}).execute()
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    points, problems = {}, []
    for index, cell in enumerate(nb.cells):
        meta = cell.get("metadata", {}).get("nbgrader", {})
        if not meta.get("grade"):
            problem, note = lesson_cell_problem(index, cell)
            if note:
                print(note)
            if problem:
                problems.append(problem)
            continue
        counted = _criteria(cell)
        errors = [o for o in cell.get("outputs", []) if o.get("output_type") == "error"]
        if counted is None or counted[0] != counted[1] or errors:
            detail = (f"{errors[0]['ename']}: {errors[0]['evalue']}" if errors else
                      "no report" if counted is None else f"{counted[0]}/{counted[1]} criteria")
            problems.append(f"{meta['grade_id']}: {detail}")
        else:
            points[meta["grade_id"]] = counted[1]
    if problems:
        raise ValueError(f"{chapter.name}: the instructor source does not run cleanly: "
                         + "; ".join(problems))
    return points


def release_chapters(chapters: list[str] | None, course_dir: Path, timeout: int):
    """Validate and release the chosen chapters: (released names, seconds each took to validate,
    why the others were not released). Raises ``SystemExit`` if nbgrader fails or a solution leaks."""
    build = student_build.build(course_dir / "student_build")
    print(student_build.check_imports(build).strip())
    made = make_sources(chapters, course_dir)
    points, seconds, failed = {}, {}, []
    for chapter in made:
        print(f"{chapter.name}: running the instructor source in a fresh kernel ...", flush=True)
        started = time.monotonic()
        try:
            points[chapter.name] = validate(chapter, course_dir, build, timeout)
        except ValueError as exc:
            failed.append(str(exc))
            print(f"NOT RELEASED: {exc}")
            continue
        finally:
            seconds[chapter.name] = time.monotonic() - started
        print(f"{chapter.name}: reference solutions pass, points {points[chapter.name]} "
              f"({seconds[chapter.name]:.0f} s)")
    made = [c for c in made if c.name in points]
    if made:
        make_sources([c.name for c in made], course_dir, points)
    api = _api(course_dir)
    for chapter in made:
        result = api.generate_assignment(chapter.name, force=True, create=True)
        if not result["success"]:
            raise SystemExit(f"nbgrader generate_assignment {chapter.name} failed:\n{result['log']}")
        print(f"{chapter.name}: released to {course_dir / 'release' / chapter.name}")
    leaks = student_build.find_solutions(course_dir / "release") + student_build.find_solutions(build)
    if leaks:
        raise SystemExit("reference solutions found in the release:\n  " + "\n  ".join(leaks))
    print(f"no reference solution in {course_dir / 'release'} or {build}")
    return [c.name for c in made], seconds, failed


def release(chapters: list[str] | None, course_dir: Path, timeout: int) -> None:
    _, _, failed = release_chapters(chapters, course_dir, timeout)
    if failed:
        raise SystemExit("not released:\n  " + "\n  ".join(failed))


# ---------------------------------------------------------------------- grading
def _max_points(course_dir: Path, assignment: str) -> dict[str, float]:
    from nbgrader.api import Gradebook, MissingEntry

    with Gradebook(f"sqlite:///{course_dir / 'gradebook.db'}") as gb:
        try:
            found = gb.find_assignment(assignment)
        except MissingEntry:
            raise SystemExit(f"{assignment} is not in the gradebook: run "
                             f"`python tools/assignments.py release {assignment}` first") from None
        return {cell.name: float(cell.max_score) for nb in found.notebooks for cell in nb.grade_cells}


def _submission(folder: Path, assignment: str) -> Path | None:
    """The folder holding the student's ``<assignment>.ipynb``."""
    for candidate in (folder / assignment, folder):
        if (candidate / f"{assignment}.ipynb").is_file():
            return candidate
    return None


def _wait_showing_progress(child, record: str, student: str, wall_clock: int) -> bool:
    """Wait for a grading process to exit, printing each test cell as it starts and, at least every
    PROGRESS_EVERY_S, the cell being run (from the run record GuardedExecute keeps); False if the wall
    clock ran out first."""
    from course_helpers.core.waiting import poll_until

    started, shown, said = time.monotonic(), [], 0.0

    def finished() -> bool:
        nonlocal said
        try:
            now = json.loads(Path(record).read_text())
        except (OSError, ValueError):  # not written yet
            now = {}
        seconds = time.monotonic() - started
        for test in now.get("tests_started", [])[len(shown):]:
            shown.append(test)
            said = seconds
            print(f"    {student}: {test['test']} (cell {test['cell'] + 1} of {test['cells']}) "
                  f"started after {seconds:.0f} s", flush=True)
        if seconds - said >= PROGRESS_EVERY_S and child.alive:
            said = seconds
            running = now.get("running")
            where = f"cell {running['cell'] + 1} of {running['cells']}" if running else "starting the kernel"
            print(f"    {student}: {where} after {seconds:.0f} s", flush=True)
        return not child.alive

    return poll_until(finished, wall_clock, period=1.0)


def grade_one(course_dir: Path, assignment: str, student: str, sub: Path, out: Path, build: Path,
              timeout: int, wall_clock: int, max_points: dict[str, float]):
    """Autograde one submission in a process of its own; sweep afterwards; return its results and log."""
    from course_helpers.core import processes

    target = course_dir / "submitted" / student / assignment
    if sub.resolve() != target.resolve():  # `nbgrader collect` puts them in place already
        shutil.rmtree(target, ignore_errors=True)
        shutil.copytree(sub, target, ignore=shutil.ignore_patterns(".ipynb_checkpoints", "__pycache__"))
    run = isolation.Run(student)
    env = isolation.student_env(run, str(build))
    argv = processes.program_argv(sys.executable, str(AUTOGRADE_ONE), str(course_dir), assignment, student,
                                  "--timeout", str(timeout), "--record", run.record)
    failure = ""
    started = time.monotonic()
    # Its output goes to a file, not a pipe: a process the student's code detached may hold the
    # file open for as long as it likes without keeping the grader waiting.
    child = processes.start(f"grade-{student}", argv, group="grading", env=env, cwd=str(course_dir),
                            channel=False)
    if _wait_showing_progress(child, run.record, student, wall_clock):
        if child.returncode != 0:
            failure = f"{results.NOT_GRADED}: " + " / ".join(child.log().strip().splitlines()[-3:])
    else:
        child.kill()
        failure = f"{results.PAST_WALL_CLOCK} of {wall_clock} s and was stopped"
    seconds = time.monotonic() - started
    (out / "logs").mkdir(parents=True, exist_ok=True)
    (out / "logs" / f"{student}.log").write_text(child.log(), encoding="utf-8")
    child.stop()
    record = json.loads(Path(run.record).read_text()) if Path(run.record).exists() else {}
    # what the student's kernel left running: killed by autograde_one before it exited, or now
    left = record.get("killed_after_run", []) + isolation.sweep(run.marker)
    domains = record.get("domains", [])
    held = isolation.domains_left(domains, run.marker)
    tmp_removed = isolation.remove_tmp(run)
    result = results.collect(course_dir, assignment, student, max_points, failure)
    result.seconds = seconds
    if left:
        result.notes.append(f"killed {len(left)} process(es) left after the run: " + "; ".join(left))
    if held:
        result.notes.append(f"domain(s) {held} still held after the sweep")
    if not tmp_removed:
        result.notes.append(f"temporary folder {run.tmp} could not be removed")
    feedback = None
    if not failure:
        made = _api(course_dir).generate_feedback(assignment, student, force=True)
        html = course_dir / "feedback" / student / assignment / f"{assignment}.html"
        if made["success"] and html.exists():
            feedback = out / "feedback" / f"{student}.html"
            feedback.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(html, feedback)
    entry = {"student": student, "seconds": round(seconds, 1), "failure": failure, "marker": run.marker,
             "events": record.get("events", []), "kernels": record.get("kernels", []),
             "domains": domains, "domains_still_held": held,
             "killed_after_run": left, "tmp_removed": tmp_removed,
             "feedback": str(feedback) if feedback else None}
    return result, entry


def grade(submissions: Path, assignment: str, course_dir: Path, timeout: int, wall_clock: int,
          out: Path | None) -> Path:
    max_points = _max_points(course_dir, assignment)
    build = course_dir / "student_build"
    if not (build / "course_helpers").is_dir():
        student_build.build(build)
    out = out or course_dir / "graded" / assignment
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    isolation.become_subreaper()
    table, log = [], []
    for folder in sorted(p for p in submissions.iterdir() if p.is_dir()):
        sub = _submission(folder, assignment)
        if sub is None:
            print(f"{folder.name}: no {assignment}.ipynb, skipped")
            continue
        print(f"{folder.name}: grading {assignment} ...", flush=True)
        result, entry = grade_one(course_dir, assignment, folder.name, sub, out, build, timeout, wall_clock,
                                  max_points)
        table.append(result)
        log.append(entry)
        lost = {g: r for g, (p, m, r) in result.grades.items() if p < m}
        print(f"{folder.name}: {result.total:g}/{sum(max_points.values()):g} in {result.seconds:.0f} s"
              + "".join(f"\n    {g}: {r}" for g, r in lost.items())
              + "".join(f"\n    note: {n}" for n in result.notes))
    path = results.write_csv(out / "grades.csv", table, max_points)
    (out / "log.json").write_text(json.dumps(log, indent=1) + "\n", encoding="utf-8")
    print(f"grade table: {path}")
    return path


# ---------------------------------------------------------------------- grade-all (maintainers)
# What grade-all generates in its course directory, removed before it starts, so each run starts afresh.
GENERATED = ("source", "release", "student_build", "submitted", "autograded", "feedback", "graded",
             "handed_in", "gradebook.db", "grade-all.md")


def _minutes(seconds: float) -> str:
    return f"{int(seconds // 60)} min {seconds % 60:02.0f} s"


def grade_all(chapters: list[str] | None, course_dir: Path, timeout: int, wall_clock: int,
              release_timeout: int) -> int:
    """Release the chosen chapters (all with a graded exercise by default), grade each one's untouched
    starting code and then its reference, and judge the grade tables (:mod:`tools.grading.verdict`).
    Prints the table and each chapter's time; returns 1 if anything is wrong, with what and where."""
    if course_dir == COURSE_DIR.resolve():
        raise SystemExit(f"grade-all grades made-up students: give it a course directory other than "
                         f"{course_dir}")
    for name in GENERATED:
        path = course_dir / name
        shutil.rmtree(path) if path.is_dir() else path.unlink(missing_ok=True)
    started = time.monotonic()
    released, validation, not_released = release_chapters(chapters, course_dir, release_timeout)
    problems = [f"not released: {why}" for why in not_released]
    lines, notes, grading = [], [], {}
    for number, assignment in enumerate(released, 1):
        print(f"\n[{number}/{len(released)}] {assignment}: grading the starting code, then the reference",
              flush=True)
        began = time.monotonic()
        folder = course_dir / "handed_in" / assignment
        try:
            students = {verdict.STARTING: {},
                        verdict.REFERENCE: handin.reference_answers(course_dir, assignment)}
            handin.hand_in(course_dir, assignment, students, folder)
            max_points = _max_points(course_dir, assignment)
            graded = results.read_csv(grade(folder, assignment, course_dir, timeout, wall_clock, None),
                                      max_points)
            judged = verdict.judge(assignment, max_points, graded)
            notes += verdict.notes(assignment, graded)
        except (Exception, SystemExit) as exc:  # one chapter's trouble never stops the others
            judged = [verdict.Line(assignment, "-", 0, problems=[f"{assignment}: grading stopped: {exc}"])]
        grading[assignment] = time.monotonic() - began
        lines += judged
        print(verdict.table(judged))
        print(f"{assignment}: {'FAILED' if verdict.problems(judged) else 'graded right'} "
              f"(validation {validation[assignment]:.0f} s, grading {grading[assignment]:.0f} s)", flush=True)
    problems += verdict.problems(lines)
    times = ["| assignment | validation | grading (2 submissions) | total |", "|---|---:|---:|---:|"]
    for name, seconds in validation.items():
        graded = grading.get(name, 0.0)
        times.append(f"| {name} | {seconds:.0f} s | {graded:.0f} s | {seconds + graded:.0f} s |")
    total = _minutes(time.monotonic() - started)
    summary = "\n\n".join([
        f"grade-all: {len(released)} of {len(validation)} chapter(s) released and graded, {total} in all",
        verdict.table(lines) if lines else "(no chapter was graded)",
        "\n".join(times),
        *(["Notes on the runs (not failures):\n" + "\n".join(f"- {n}" for n in notes)] if notes else []),
        ("PROBLEMS:\n" + "\n".join(f"- {p}" for p in problems)) if problems else
        "Every reference earned full marks and every starting code was marked down on every exercise."])
    (course_dir / "grade-all.md").write_text(summary + "\n", encoding="utf-8")
    print("\n" + summary + f"\n\n(also in {course_dir / 'grade-all.md'}; grade tables and feedback in "
          f"{course_dir / 'graded'})")
    return 1 if problems else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Graded assignments with nbgrader, from the notebooks.")
    parser.add_argument("--course-dir", type=Path, default=None,
                        help=f"nbgrader course directory (default: {COURSE_DIR}; "
                             f"for grade-all {GRADE_ALL_DIR})")
    commands = parser.add_subparsers(dest="command", required=True)
    p = commands.add_parser("source", help="write the instructor source from the notebooks")
    p.add_argument("chapters", nargs="*")
    p = commands.add_parser("release", help="validate the source and generate the student release")
    p.add_argument("chapters", nargs="*")
    p.add_argument("--timeout", type=int, default=180, help="seconds per cell of the validation run")
    p = commands.add_parser("grade", help="autograde a folder of submissions")
    p.add_argument("submissions", type=Path)
    p.add_argument("--assignment", required=True, help="e.g. 04_services")
    p.add_argument("--timeout", type=int, default=120, help="seconds per cell")
    p.add_argument("--wall-clock", type=int, default=900, help="seconds per submission")
    p.add_argument("--out", type=Path, default=None, help="default: <course dir>/graded/<assignment>")
    p = commands.add_parser("grade-all", help="maintainers: release, then grade the reference and the "
                                              "starting code of every chapter and check the scores")
    p.add_argument("chapters", nargs="*")
    p.add_argument("--timeout", type=int, default=120, help="seconds per cell of a graded submission")
    p.add_argument("--wall-clock", type=int, default=900, help="seconds per submission")
    p.add_argument("--release-timeout", type=int, default=180, help="seconds per cell of the validation run")
    args = parser.parse_args(argv)
    course_dir = (args.course_dir or (GRADE_ALL_DIR if args.command == "grade-all" else COURSE_DIR)).resolve()
    course_dir.mkdir(parents=True, exist_ok=True)
    if not (course_dir / "nbgrader_config.py").is_file():
        shutil.copyfile(COURSE_DIR / "nbgrader_config.py", course_dir / "nbgrader_config.py")
    if args.command == "source":
        make_sources(args.chapters, course_dir)
    elif args.command == "release":
        release(args.chapters, course_dir, args.timeout)
    elif args.command == "grade-all":
        return grade_all(args.chapters, course_dir, args.timeout, args.wall_clock, args.release_timeout)
    else:
        grade(args.submissions.resolve(), args.assignment, course_dir, args.timeout, args.wall_clock,
              args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
