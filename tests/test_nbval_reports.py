"""A failed notebook cell's report says what the cell wrote to stderr, and a cell that builds is bounded
by its builder's own limit (``notebooks/conftest.py``).

nbval fails a cell whose run wrote to stderr when its committed outputs have no stderr, and says only
"Unexpected output fields from running code: {'stderr'}". A fresh-clone CI run failed that way once,
inside the image, with nothing to tell what was written.
"""

from __future__ import annotations

from .nbval_runs import run_nbval


def _notebook(source: str, metadata: dict | None = None) -> dict:
    return {
        "cells": [{"cell_type": "code", "execution_count": 1, "id": "c1", "metadata": metadata or {},
                   "outputs": [], "source": source}],
        "metadata": {"kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"}},
        "nbformat": 4, "nbformat_minor": 5,
    }


def test_a_cell_that_wrote_to_stderr_fails_with_what_it_wrote(tmp_path):
    run = run_nbval(tmp_path, _notebook("import sys\nprint('the port went away', file=sys.stderr)"))
    assert run.returncode != 0, run.stdout[-3000:]
    assert "Unexpected output fields" in run.stdout, run.stdout[-3000:]
    assert "what the cell wrote to stderr" in run.stdout, run.stdout[-3000:]
    assert "the port went away" in run.stdout, run.stdout[-3000:]


def test_a_quiet_cell_passes_and_adds_nothing(tmp_path):
    run = run_nbval(tmp_path, _notebook("x = 1"))
    assert run.returncode == 0, run.stdout[-3000:]
    assert "what the cell wrote to stderr" not in run.stdout


SLOWER_THAN_THE_CELL_TIMEOUT = "import time\ntime.sleep(4)"  # with --nbval-cell-timeout=1 --timeout=1 below
TIGHT = ("--nbval-cell-timeout=1", "--timeout=1")


def test_a_build_cell_is_bounded_by_its_builders_limit_not_the_cell_timeout(tmp_path):
    builds = _notebook(SLOWER_THAN_THE_CELL_TIMEOUT, {"course_builds": "rcl_program"})
    run = run_nbval(tmp_path, builds, *TIGHT)
    assert run.returncode == 0, run.stdout[-3000:]


def test_a_cell_that_does_not_build_keeps_the_cell_timeout(tmp_path):
    run = run_nbval(tmp_path, _notebook(SLOWER_THAN_THE_CELL_TIMEOUT), *TIGHT)
    assert run.returncode != 0, run.stdout[-3000:]
    assert "Timeout" in run.stdout, run.stdout[-3000:]


def test_an_unknown_builder_is_refused_by_name(tmp_path):
    run = run_nbval(tmp_path, _notebook("x = 1", {"course_builds": "make"}))
    assert run.returncode != 0
    assert "'make' is not a known builder" in run.stdout + run.stderr, run.stdout[-3000:] + run.stderr[-3000:]
