"""Every notebook runs twice in one kernel ("Run All" twice) without errors or duplicates."""

from __future__ import annotations

import glob
import os

import nbformat
import pytest

from .conftest import REPO
from .kernel_session import KernelSession

NOTEBOOKS = sorted(glob.glob(os.path.join(REPO, "notebooks", "*.ipynb")))

AFTER_CHECK = """
import threading, collections
_rt = get_runtime()
_names = [ns.rstrip('/') + '/' + n for n, ns in _rt.graph.get_node_names_and_namespaces()]
_dupes = sorted(n for n, c in collections.Counter(_names).items() if c > 1)
_threads = sum(t.name == 'ros-executor' for t in threading.enumerate())
print('duplicates', _dupes, 'executor threads', _threads)
"""


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[os.path.basename(p) for p in NOTEBOOKS])
def test_run_all_twice_in_one_kernel(path):
    cells = [c.source for c in nbformat.read(path, as_version=4).cells if c.cell_type == "code"]
    session = KernelSession(cwd=os.path.dirname(path))
    try:
        for run in (1, 2):
            for index, source in enumerate(cells):
                out, error = session.run(source, timeout=300)
                assert error is None, f"run {run}, cell {index}: {error}\n{out[-2000:]}"
        out, error = session.run("from course_helpers import get_runtime\n" + AFTER_CHECK)
        assert error is None, out
        assert "duplicates [] executor threads 1" in out, out
    finally:
        code, stderr = session.shutdown()
    assert "terminate called" not in stderr
