"""Run notebooks top to bottom in a fresh kernel and save them with their outputs.

Maintainers use this (``make execute`` or ``python tools/execute_notebooks.py notebooks/03_topics.ipynb``)
so that committed notebooks carry the outputs and plots that web readers see,
and that strict nbval then compares against.
"""

from __future__ import annotations

import os
import sys
import time
from datetime import datetime

import nbformat
from nbclient import NotebookClient

from tools.kernels import AsyncPrivateSocketKernelManager

RUN_TIME_KEY = "course_run_s"  # a code cell's run time, rounded (tools/reading_path.py adds them up)


def run(notebook: nbformat.NotebookNode, cwd: str, timeout: int = 600) -> None:
    """Run every cell of ``notebook`` in a fresh kernel started in ``cwd``, filling in its outputs,
    its widget state (``metadata.widgets``) and each code cell's run time (``metadata.course_run_s``,
    seconds rounded to 0.1, instead of nbclient's timestamps)."""
    os.environ.pop("ROS_DOMAIN_ID", None)
    client = NotebookClient(notebook, timeout=timeout, kernel_name="python3",
                            kernel_manager_class=AsyncPrivateSocketKernelManager,  # no port to collide on
                            resources={"metadata": {"path": cwd}},
                            store_widget_state=True, record_timing=True)
    client.execute()
    for cell in notebook.cells:
        stamps = cell.metadata.pop("execution", None)
        if cell.cell_type == "code" and stamps and "iopub.execute_input" in stamps \
                and "shell.execute_reply" in stamps:
            started, ended = (datetime.fromisoformat(stamps[key].replace("Z", "+00:00"))
                              for key in ("iopub.execute_input", "shell.execute_reply"))
            cell.metadata[RUN_TIME_KEY] = round((ended - started).total_seconds(), 1)


def execute(path: str, timeout: int = 600) -> float:
    """Execute one notebook in place; return the seconds it took."""
    notebook = nbformat.read(path, as_version=4)
    start = time.monotonic()
    run(notebook, os.path.dirname(os.path.abspath(path)), timeout)
    nbformat.write(notebook, path)
    return time.monotonic() - start


def main(paths: list[str]) -> int:
    if not paths:
        print("usage: python tools/execute_notebooks.py NOTEBOOK.ipynb [...]")
        return 2
    for path in paths:
        print(f"executing {path} ...", flush=True)
        seconds = execute(path)
        print(f"  saved with outputs in {seconds:.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
