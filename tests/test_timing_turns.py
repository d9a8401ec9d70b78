"""The timing stage's turns (tests/timing_turns.py), held by real processes on real flock locks."""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys

import pytest

from course_helpers.core.waiting import poll_until
from tests.timing_turns import STAGE, TURNS_VARIABLE, TURNSTILE, open_lock

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# a test process in its turn: says when it holds it, then keeps it until its stdin ends
HOLDER = """
import sys
from tests.timing_turns import turn
with turn(alone=sys.argv[1] == 'alone'):
    print('holding', flush=True)
    sys.stdin.read()
print('released', flush=True)
"""


@pytest.fixture
def hold(tmp_path, monkeypatch):
    """``hold(kind)`` starts a test process that takes its turn, ``shared`` or ``alone``, in fresh locks."""
    monkeypatch.setenv(TURNS_VARIABLE, str(tmp_path))
    started = []

    def hold(kind: str) -> subprocess.Popen:
        process = subprocess.Popen([sys.executable, "-c", HOLDER, kind], cwd=REPO, text=True,
                                   stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        started.append(process)
        return process

    yield hold
    for process in started:
        process.kill()
        process.wait()


def _free(name: str, how: int) -> bool:
    """Whether this process could take the lock ``name`` now (without waiting); it lets it go at once."""
    fd = open_lock(name)
    try:
        fcntl.flock(fd, how | fcntl.LOCK_NB)
        return True
    except BlockingIOError:
        return False
    finally:
        os.close(fd)


def _says(process: subprocess.Popen, word: str) -> None:
    assert process.stdout.readline().strip() == word


def test_a_test_that_runs_alone_waits_for_the_others_and_holds_off_the_next(hold):
    first = hold("shared")
    _says(first, "holding")
    second = hold("shared")
    _says(second, "holding")  # two timing tests share the stage
    assert not _free(STAGE, fcntl.LOCK_EX)
    alone = hold("alone")
    # It waits for the stage and keeps the turnstile meanwhile, so no further test overtakes it.
    waiting = poll_until(lambda: not _free(TURNSTILE, fcntl.LOCK_EX), 10)
    assert waiting, "it is not waiting at the turnstile (it took the stage beside the others?)"
    first.stdin.close()
    _says(first, "released")
    assert not _free(TURNSTILE, fcntl.LOCK_EX)  # the other test still runs: it still waits
    second.stdin.close()
    _says(second, "released")
    _says(alone, "holding")
    assert not _free(STAGE, fcntl.LOCK_SH)  # nothing else runs beside it
    alone.stdin.close()
    _says(alone, "released")
    assert _free(STAGE, fcntl.LOCK_EX) and _free(TURNSTILE, fcntl.LOCK_EX)


def test_a_killed_test_process_gives_up_its_turn(hold):
    alone = hold("alone")
    _says(alone, "holding")
    alone.kill()
    alone.wait()
    assert _free(STAGE, fcntl.LOCK_EX)


def test_runs_alone_without_timing_is_refused_at_collection(tmp_path):
    loose = "import pytest\n\n\n@pytest.mark.runs_alone\ndef test_x():\n    pass\n"
    (tmp_path / "test_loose.py").write_text(loose)
    done = subprocess.run([sys.executable, "-m", "pytest", "-p", "tests.conftest", "--collect-only", "-q",
                           "--rootdir", str(tmp_path), str(tmp_path / "test_loose.py")],
                          cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode != 0, done.stdout
    assert "marked 'runs_alone' but not 'timing'" in done.stdout + done.stderr, done.stdout + done.stderr
