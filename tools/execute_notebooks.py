"""Run notebooks top to bottom in a fresh kernel and save them with their outputs.

Maintainers use this (``make execute`` or ``python tools/execute_notebooks.py notebooks/03_topics.ipynb``)
so that committed notebooks carry the outputs and plots that web readers see,
and that strict nbval then compares against.
"""

from __future__ import annotations

import os
import sys
import time

import nbformat
from nbclient import NotebookClient


def run(notebook: nbformat.NotebookNode, cwd: str, timeout: int = 600) -> None:
    """Run every cell of ``notebook`` in a fresh kernel started in ``cwd``, filling in its outputs
    and its widget state (``metadata.widgets``)."""
    os.environ.pop("ROS_DOMAIN_ID", None)
    client = NotebookClient(notebook, timeout=timeout, kernel_name="python3",
                            resources={"metadata": {"path": cwd}},
                            store_widget_state=True, record_timing=False)
    client.execute()


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
