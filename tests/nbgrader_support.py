"""What the nbgrader test files share: a chapter (04 unless told otherwise) released into a
temporary course, the misbehaving answers, handing in (``tools.grading.handin``) and grading with
``tools/assignments.py``.

The students of chapter 04 are split over ``test_nbgrader.py`` and ``test_nbgrader_misbehaving.py`` so
that two parallel workers grade them at the same time; each file releases its own course.
``test_nbgrader_ch10.py`` releases and grades chapter 10.
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
from tools.grading import handin, isolation, results, source, student_build, verdict  # noqa: F401
from tools.grading.handin import EXTRA_CELL as EXTRA  # noqa: F401 (a cell the student added at the end)
from tools.grading.handin import grade_cells, solved  # noqa: F401
from tools.grading.source import BEGIN  # noqa: F401

from .conftest import REPO

TOOLS = Path(REPO) / "tools"

CHAPTER = "04_services"
EX1, EX2 = "ex1_BatteryMonitor", "ex2_SumRelay"
CELL_TIMEOUT_S = 90  # a hang bound, not a measurement: chapter 04's slowest cell takes about 10 s idle,
# so a busy machine never reaches it; a hanging answer (HANGS) costs this long

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


def tool(*args: str, timeout: float) -> str:
    code, output = processes.run([sys.executable, str(TOOLS / "assignments.py"), *args], cwd=REPO,
                                 timeout=timeout)
    assert code == 0, output
    return output


def release_course(tmp_path_factory, chapter: str = "04") -> tuple[Path, str]:
    """A chapter (04) released into a new course directory; the directory and the tool's output."""
    course_dir = tmp_path_factory.mktemp("course")
    output = tool("--course-dir", str(course_dir), "release", chapter, timeout=600)
    return course_dir, output


def released_course(chapter: str = "04"):
    """A module-scoped fixture ``course``: ``chapter`` released into a new course directory, as
    (the directory, the tool's output). A test file says ``course = released_course("10")``."""
    @pytest.fixture(scope="module", name="course")
    def course(tmp_path_factory):
        return release_course(tmp_path_factory, chapter)

    return course


def graded_students(students_of, chapter: str = CHAPTER, cell_timeout: int = CELL_TIMEOUT_S):
    """A module-scoped fixture ``graded`` (on ``course``): the students ``students_of(course_dir)``
    returns ({student: {exercise: answer}}) handed in and graded, as :func:`grade_students` returns."""
    @pytest.fixture(scope="module", name="graded")
    def graded(course, tmp_path_factory):
        course_dir, _ = course
        return grade_students(course_dir, students_of(course_dir), tmp_path_factory, chapter=chapter,
                              cell_timeout=cell_timeout)

    return graded


def solutions(course_dir: Path) -> dict[str, str]:
    """Each exercise finished: its starting code and the reference, as one cell."""
    answers = handin.reference_answers(course_dir, CHAPTER)
    assert sorted(answers) == [EX1, EX2], answers
    return answers


def hand_in(course_dir: Path, students: dict[str, dict[str, str]], submissions: Path,
            chapter: str = CHAPTER) -> Path:
    """Write each student's notebook: the release with their answers in the exercise cells."""
    return handin.hand_in(course_dir, chapter, students, submissions)


def grade(course_dir: Path, submissions: Path, out: Path, wall_clock: int, chapter: str = CHAPTER,
          cell_timeout: int = CELL_TIMEOUT_S):
    output = tool("--course-dir", str(course_dir), "grade", str(submissions), "--assignment", chapter,
                   "--timeout", str(cell_timeout), "--wall-clock", str(wall_clock), "--out", str(out),
                   timeout=1000)
    with open(out / "grades.csv", newline="") as f:
        rows = {row["student"]: row for row in csv.DictReader(f)}
    log = {entry["student"]: entry for entry in json.loads((out / "log.json").read_text())}
    return rows, log, output


def grade_students(course_dir: Path, students: dict[str, dict[str, str]], tmp_path_factory,
                   chapter: str = CHAPTER, cell_timeout: int = CELL_TIMEOUT_S):
    """Hand in these students' answers and grade them (10 min wall clock each):
    (rows, log, output folder, the tool's output)."""
    submissions = hand_in(course_dir, students, tmp_path_factory.mktemp("submissions"), chapter)
    out = course_dir / "graded"
    rows, log, output = grade(course_dir, submissions, out, wall_clock=600, chapter=chapter,
                              cell_timeout=cell_timeout)
    return rows, log, out, output


def alive_runs(markers: set[str]) -> list:
    """Command lines of processes that carry one of these grading runs' markers (another test
    file may be grading at the same time: its runs are not ours to judge)."""
    alive = []
    for proc in psutil.process_iter():
        try:
            if proc.environ().get(isolation.MARKER) in markers:
                alive.append(proc.cmdline())
        except psutil.Error:
            pass
    return alive


def points(rows: dict, student: str, exercise: str) -> float:
    return float(rows[student][exercise + "_check"])


def reason(rows: dict, student: str, exercise: str) -> str:
    return rows[student][exercise + "_check reason"]


def assert_nothing_left(log: dict) -> None:
    """Every graded kernel held a domain that is free again, its temporary folder is gone, and no
    process of any grading run is alive."""
    for student, entry in log.items():
        assert entry["failure"] == "", entry
        assert entry["domains"], f"{student}'s kernel held no domain lock"
        assert entry["domains_still_held"] == [] and entry["tmp_removed"], entry
    assert_no_process_left(log)


def assert_no_process_left(log: dict) -> None:
    """No process of the runs in this grading log is alive."""
    markers = {entry["marker"] for entry in log.values()}
    assert markers, "the log names no grading run"
    # on a loaded machine a process of the last run can take a while to go (seen: under a minute)
    assert poll_until(lambda: alive_runs(markers) == [], 90), \
        f"processes of a grading run are still alive: {alive_runs(markers)}"
