"""A failed notebook cell's report says what the cell wrote to stderr (``notebooks/conftest.py``).

nbval fails a cell whose run wrote to stderr when its committed outputs have no stderr, and says only
"Unexpected output fields from running code: {'stderr'}". A fresh-clone CI run failed that way once,
inside the image, with nothing to tell what was written.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

from .conftest import REPO


def _notebook(source: str) -> dict:
    return {
        "cells": [{"cell_type": "code", "execution_count": 1, "id": "c1", "metadata": {}, "outputs": [],
                   "source": source}],
        "metadata": {"kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"}},
        "nbformat": 4, "nbformat_minor": 5,
    }


def _nbval(tmp_path, source: str) -> subprocess.CompletedProcess:
    shutil.copy(os.path.join(REPO, "notebooks", "conftest.py"), tmp_path / "conftest.py")
    (tmp_path / "cell.ipynb").write_text(json.dumps(_notebook(source)))
    argv = [sys.executable, "-m", "pytest", "--nbval", "--nbval-current-env", "-p", "no:cacheprovider", "-q",
            str(tmp_path / "cell.ipynb")]
    return subprocess.run(argv, cwd=str(tmp_path), env={**os.environ, "COURSE_NBVAL_RERUN": "0"},
                          capture_output=True, text=True, timeout=180)


def test_a_cell_that_wrote_to_stderr_fails_with_what_it_wrote(tmp_path):
    run = _nbval(tmp_path, "import sys\nprint('the port went away', file=sys.stderr)")
    assert run.returncode != 0, run.stdout[-3000:]
    assert "Unexpected output fields" in run.stdout, run.stdout[-3000:]
    assert "what the cell wrote to stderr" in run.stdout, run.stdout[-3000:]
    assert "the port went away" in run.stdout, run.stdout[-3000:]


def test_a_quiet_cell_passes_and_adds_nothing(tmp_path):
    run = _nbval(tmp_path, "x = 1")
    assert run.returncode == 0, run.stdout[-3000:]
    assert "what the cell wrote to stderr" not in run.stdout
