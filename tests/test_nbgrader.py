"""Graded assignments end to end with real nbgrader and real ROS nodes (``tools/assignments.py``).

Chapter 04 (two exercises, real service nodes) is released into a temporary course directory
with nbgrader's own generate_assignment, then five students hand it in: one correct, one
unchanged (wrong), and three whose code misbehaves in one exercise - it hangs, kills the
kernel, floods the output, or leaves processes running. Grading must give each misbehaving
exercise zero with its reason, still grade the other exercise, and leave nothing behind.
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import psutil
import pytest

from course_helpers.core import processes
from course_helpers.core.waiting import poll_until

from .conftest import REPO

TOOLS = Path(REPO) / "tools"
sys.path.insert(0, str(TOOLS))

from grading import isolation, source, student_build  # noqa: E402
from grading.source import BEGIN, END  # noqa: E402

CHAPTER = "04_services"
EX1, EX2 = "ex1_BatteryMonitor", "ex2_SumRelay"
CELL_TIMEOUT_S = 40  # the slowest cell of chapter 04 takes about 10 s
pytestmark = [pytest.mark.slow, pytest.mark.timeout(1200), pytest.mark.xdist_group("nbgrader")]

HANGS = """
import time


class BatteryMonitor(Node):
    def __init__(self):
        super().__init__('battery_monitor')
        time.sleep(3600)  # waits for something that never comes
"""
CRASHES = """
import os
import signal


class BatteryMonitor(Node):
    def __init__(self):
        super().__init__('battery_monitor')
        os.kill(os.getpid(), signal.SIGKILL)  # the kernel dies
"""
FLOODS = """
class BatteryMonitor(Node):
    def __init__(self):
        super().__init__('battery_monitor')
        for i in range(10**6):
            print('debug', i, 'x' * 100)
"""
RUNAWAY_LINE = "        subprocess.Popen(['sh', '-c', 'sleep 600 &'])  # a detached process nobody stops\n"
# a daemon of its own session: jupyter_client's kill of the kernel's process group misses it
LAST_CELL = "import subprocess\n\nsubprocess.Popen(['sh', '-c', 'sleep 700 &'], start_new_session=True)\n"
EXTRA = "extra cell"  # key of an answer that is a cell the student added at the end


def _tool(*args: str, timeout: float) -> str:
    code, output = processes.run([sys.executable, str(TOOLS / "assignments.py"), *args], cwd=REPO,
                                 timeout=timeout)
    assert code == 0, output
    return output


def _grade_cells(nb: dict) -> dict[str, dict]:
    return {c["metadata"]["nbgrader"]["grade_id"]: c for c in nb["cells"] if "nbgrader" in c["metadata"]}


def _solved(source_cell: dict) -> str:
    """A student's finished exercise: the starting code and the reference, as one cell."""
    lines = "".join(source_cell["source"]).splitlines()
    return "\n".join(line for line in lines if line.strip() not in (BEGIN, END)) + "\n"


@pytest.fixture(scope="module")
def course(tmp_path_factory):
    course_dir = tmp_path_factory.mktemp("course")
    output = _tool("--course-dir", str(course_dir), "release", "04", timeout=600)
    return course_dir, output


def _solutions(course_dir: Path) -> dict[str, str]:
    source = _grade_cells(json.loads((course_dir / "source" / CHAPTER / f"{CHAPTER}.ipynb").read_text()))
    return {EX1: _solved(source[EX1]), EX2: _solved(source[EX2])}


def _hand_in(course_dir: Path, students: dict[str, dict[str, str]], submissions: Path) -> Path:
    """Write each student's notebook: the release with their answers in the exercise cells."""
    release = json.loads((course_dir / "release" / CHAPTER / f"{CHAPTER}.ipynb").read_text())
    for student, answers in students.items():
        nb = json.loads(json.dumps(release))
        for grade_id, cell in _grade_cells(nb).items():
            if grade_id in answers:
                cell["source"] = answers[grade_id]
        if EXTRA in answers:
            nb["cells"].append({"cell_type": "code", "execution_count": None, "id": "student-extra",
                                "metadata": {}, "outputs": [], "source": answers[EXTRA]})
        folder = submissions / student / CHAPTER
        folder.mkdir(parents=True)
        (folder / f"{CHAPTER}.ipynb").write_text(json.dumps(nb, indent=1))
    return submissions


def _grade(course_dir: Path, submissions: Path, out: Path, wall_clock: int):
    output = _tool("--course-dir", str(course_dir), "grade", str(submissions), "--assignment", CHAPTER,
                   "--timeout", str(CELL_TIMEOUT_S), "--wall-clock", str(wall_clock), "--out", str(out),
                   timeout=1000)
    with open(out / "grades.csv", newline="") as f:
        rows = {row["student"]: row for row in csv.DictReader(f)}
    log = {entry["student"]: entry for entry in json.loads((out / "log.json").read_text())}
    return rows, log, output


def _alive_runs() -> list:
    """Command lines of processes that carry a grading run's marker."""
    alive = []
    for proc in psutil.process_iter():
        try:
            if proc.environ().get(isolation.MARKER):
                alive.append(proc.cmdline())
        except psutil.Error:
            pass
    return alive


@pytest.fixture(scope="module")
def graded(course, tmp_path_factory):
    course_dir, _ = course
    solved = _solutions(course_dir)
    # the reference class comes after the starting code in the cell: change the reference
    head, tail = solved[EX2].rsplit("        super().__init__('sum_relay')\n", 1)
    runaway = f"import subprocess\n{head}        super().__init__('sum_relay')\n{RUNAWAY_LINE}{tail}"
    students = {
        "alice": solved,
        "bob": {EXTRA: LAST_CELL},  # hands in the starting code, and a process outside any exercise
        "carol": {EX1: HANGS, EX2: solved[EX2]},
        "dave": {EX1: CRASHES, EX2: solved[EX2]},
        "erin": {EX1: FLOODS, EX2: runaway},
    }
    submissions = _hand_in(course_dir, students, tmp_path_factory.mktemp("submissions"))
    out = course_dir / "graded"
    rows, log, output = _grade(course_dir, submissions, out, wall_clock=600)
    return rows, log, out, output


def test_every_exercise_of_the_notebooks_gets_its_reference_solution():
    """Static, for every chapter: each exercise found has a reference solution, and the source's
    solution and test cells are valid Python (what release would validate by running them)."""
    found = {}
    for path in source.chapter_notebooks():
        chapter = source.load_chapter(path)
        assert [e.grade_id for e in chapter.exercises if e.skipped] == [], \
            [(e.grade_id, e.skipped) for e in chapter.exercises]
        nb = source.build_source(chapter, {})
        for cell in nb["cells"]:
            if "nbgrader" in cell["metadata"]:
                lines = "".join(cell["source"]).splitlines()
                compile("\n".join(ln for ln in lines if not ln.startswith("%")), path.name, "exec")
        found[chapter.name] = len(chapter.graded)
    assert found.get(CHAPTER) == 2 and sum(found.values()) >= 10, found


def test_release_holds_no_solution_and_the_checkers_work_without_them(course):
    course_dir, output = course
    release = course_dir / "release" / CHAPTER / f"{CHAPTER}.ipynb"
    cells = _grade_cells(json.loads(release.read_text()))
    assert sorted(cells) == sorted([EX1, EX1 + "_check", EX2, EX2 + "_check"])
    for grade_id in (EX1, EX2):
        assert cells[grade_id]["metadata"]["nbgrader"]["solution"]
        assert "TODO" in "".join(cells[grade_id]["source"])  # the starting code stays
        assert BEGIN not in "".join(cells[grade_id]["source"])
        points = cells[grade_id + "_check"]["metadata"]["nbgrader"]["points"]
        assert points >= 3 and cells[grade_id + "_check"]["metadata"]["nbgrader"]["locked"]
    # the grep is not vacuous: the instructor source holds solution lines, the release none
    assert student_build.find_solutions(course_dir / "source")
    assert student_build.find_solutions(course_dir / "release") == []
    build = course_dir / "student_build"
    assert (build / "course_helpers" / "checks").is_dir()
    assert not (build / "course_helpers" / "solutions").exists()
    assert student_build.find_solutions(build) == []
    assert "course_helpers.solutions: absent" in output and "reference solutions pass" in output


def test_scores_reasons_and_feedback(graded):
    rows, log, out, output = graded
    assert sorted(rows) == ["alice", "bob", "carol", "dave", "erin"]
    full = {ex: float(rows["alice"]["max"]) for ex in (EX1, EX2)}
    max1 = float(rows["alice"][EX1 + "_check"])
    max2 = float(rows["alice"][EX2 + "_check"])
    assert max1 + max2 == full[EX1], output  # alice: every point
    assert rows["alice"][EX1 + "_check reason"] == rows["alice"][EX2 + "_check reason"] == ""

    def points(student, ex):
        return float(rows[student][ex + "_check"])

    def reason(student, ex):
        return rows[student][ex + "_check reason"]

    for ex in (EX1, EX2):  # the starting code passes some criteria, never all
        assert points("bob", ex) < (max1 if ex == EX1 else max2)
        assert reason("bob", ex).startswith("failed: "), reason("bob", ex)
    assert points("carol", EX1) == 0 and "CellTimeoutError" in reason("carol", EX1)
    assert points("dave", EX1) == 0 and "KernelDied" in reason("dave", EX1)
    assert points("erin", EX1) == 0 and "OutputLimitExceeded" in reason("erin", EX1)
    assert points("erin", EX2) == 0 and "RunawayProcesses" in reason("erin", EX2)
    assert "sleep 600" in reason("erin", EX2)
    # the misbehaving exercise costs only itself: the correct second exercise still earns its points
    assert points("carol", EX2) == max2, reason("carol", EX2)
    assert points("dave", EX2) == max2, reason("dave", EX2)
    for student in rows:
        html = (out / "feedback" / f"{student}.html").read_text()
        assert "Exercise 04.1" in html and "Exercise 04.2" in html
    assert "CellTimeoutError" in (out / "feedback" / "carol.html").read_text()
    assert "KernelDied" in (out / "feedback" / "dave.html").read_text()
    # a process started outside the exercises outlives the kernel: the sweep kills it and says so
    assert "killed 1 process(es) left after the run" in rows["bob"]["notes"]
    assert "sleep 700" in rows["bob"]["notes"]


def test_nothing_of_a_run_is_left(graded):
    rows, log, out, _ = graded
    for student, entry in log.items():
        assert entry["failure"] == "", entry
        assert entry["domains"], f"{student}'s kernel held no domain lock"
        assert entry["domains_still_held"] == [] and entry["tmp_removed"], entry
        assert not any(isolation.domain_free(d) is False and d in entry["domains"]
                       for d in entry["domains_still_held"])
    assert any(e["kind"] == "kernel restarted" for e in log["dave"]["events"])
    # on a loaded machine a process of the last run can take a while to go (seen: under a minute)
    assert poll_until(lambda: _alive_runs() == [], 90), \
        f"processes of a grading run are still alive: {_alive_runs()}"
    seconds = {s: e["seconds"] for s, e in log.items()}
    print(f"grading seconds per submission: {seconds}")


def test_a_run_past_the_wall_clock_scores_zero_and_is_swept(course, tmp_path_factory):
    """The wall clock stops nbgrader itself mid-run: every exercise scores zero with that reason,
    and nothing of the run is left (the orphaned kernel notices and exits, or the sweep kills it)."""
    course_dir, _ = course
    answers = {EX1: HANGS, EX2: _solutions(course_dir)[EX2]}  # runs at least CELL_TIMEOUT_S
    submissions = _hand_in(course_dir, {"frank": answers}, tmp_path_factory.mktemp("late"))
    rows, log, output = _grade(course_dir, submissions, course_dir / "graded-late", wall_clock=20)
    frank = rows["frank"]
    for ex in (EX1, EX2):
        assert float(frank[ex + "_check"]) == 0
        assert "wall clock of 20 s" in frank[ex + "_check reason"], output
    entry = log["frank"]
    assert entry["domains"] and entry["domains_still_held"] == [], entry
    assert entry["tmp_removed"]
    # on a loaded machine a process of the last run can take a while to go (seen: under a minute)
    assert poll_until(lambda: _alive_runs() == [], 90), \
        f"processes of a grading run are still alive: {_alive_runs()}"
