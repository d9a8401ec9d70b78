"""What ``make setup`` leaves out of the course's venv, and that nothing needed went with it."""

from __future__ import annotations

import copy
import importlib.util
from pathlib import Path

import nbformat
import pytest

from .conftest import REPO


def test_the_venv_has_no_rfc3987_syntax():
    # 2 s of CPU at every import of jsonschema (Makefile, the set-up recipe): a test worker, JupyterLab,
    # nbgrader and nbclient each pay it
    assert importlib.util.find_spec("rfc3987_syntax") is None, (
        "rfc3987-syntax is installed in this venv: make setup removes it; run "
        "`rm .venv/.course-installed && make setup`")


def test_nbformat_still_validates_a_notebook_and_rejects_a_broken_one():
    notebook = nbformat.read(Path(REPO) / "notebooks" / "00_welcome.ipynb", as_version=4)
    nbformat.validate(notebook)
    broken = copy.deepcopy(notebook)
    broken.cells[0].cell_type = "not a cell type"
    with pytest.raises(nbformat.ValidationError):
        nbformat.validate(broken)
