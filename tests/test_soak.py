"""benchmarks/soak.py reads what failed, with its message, from a real pytest run's JUnit report."""

from __future__ import annotations

import os
import subprocess
import sys

from benchmarks.soak import StageRun, failures_in, summary

from .conftest import REPO

FAILING_FILE = '''
def test_holds():
    assert 1 + 1 == 2

def test_breaks():
    assert 2 + 2 == 5, "arithmetic is off"
'''


def test_a_failed_test_is_named_with_its_message(tmp_path):
    (tmp_path / "test_sample.py").write_text(FAILING_FILE)
    junit = tmp_path / "report.xml"
    subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(tmp_path),
                    f"--junitxml={junit}"], capture_output=True, cwd=tmp_path)
    (failure,) = failures_in(str(junit))
    assert failure[0].endswith("::test_breaks") and "arithmetic is off" in failure[1]
    assert failures_in(str(tmp_path / "absent.xml")) == []


def test_a_failure_names_its_worker_and_the_files_that_ran_before_it_there(tmp_path):
    (tmp_path / "test_first.py").write_text("def test_fine():\n    pass\n")
    (tmp_path / "test_second.py").write_text(FAILING_FILE)
    junit = tmp_path / "report.xml"
    env = {**os.environ, "PYTHONPATH": REPO}
    subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "1",
                    "--dist", "loadfile", "--no-loadscope-reorder", "-p", "benchmarks.junit_workers",
                    "test_first.py", "test_second.py", f"--junitxml={junit}"],
                   capture_output=True, cwd=tmp_path, env=env)
    (failure,) = failures_in(str(junit))
    assert failure[0] == "test_second::test_breaks", failure
    assert failure[1].endswith("[on gw0, after test_first]"), failure


def test_the_summary_counts_passes_and_lists_failures():
    results = [StageRun("logic", 1, True, 300.0, "800 passed", []),
               StageRun("logic", 2, False, 320.0, "1 failed, 799 passed", [("t.py::test_x", "boom")])]
    text = summary(results, ["logic"], 2)
    assert "logic      1/2 passed; median 310 s, slowest 320 s" in text
    assert "run 2 logic: t.py::test_x: boom" in text
