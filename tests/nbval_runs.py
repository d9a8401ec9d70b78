"""Running strict nbval, with the notebooks' ``conftest.py``, on a notebook written for one test."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

from .conftest import REPO


def run_nbval(tmp_path, notebook: dict, *options: str, env: dict | None = None,
              name: str = "cell.ipynb") -> subprocess.CompletedProcess:
    """Write ``notebook`` into ``tmp_path`` beside a copy of ``notebooks/conftest.py`` and run nbval on it
    there, its first pass only, in ``env`` (this process's environment by default); the finished run, output
    captured."""
    shutil.copy(os.path.join(REPO, "notebooks", "conftest.py"), tmp_path / "conftest.py")
    (tmp_path / name).write_text(json.dumps(notebook))
    argv = [sys.executable, "-m", "pytest", "--nbval", "--nbval-current-env", "-p", "no:cacheprovider", "-q",
            *options, str(tmp_path / name)]
    first_pass = {**(os.environ if env is None else env), "COURSE_NBVAL_RERUN": "0"}
    return subprocess.run(argv, cwd=str(tmp_path), env=first_pass, capture_output=True, text=True,
                          timeout=180)
