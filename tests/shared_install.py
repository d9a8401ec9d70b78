"""Other Unix users for tests that act as them (domains, namespaces, classroom), and a course install
they can run.

This repository's .venv usually links its interpreter into /root, which other users cannot enter.
:func:`shared_venv` then makes a hard-linked copy of .venv whose interpreter is the system Python of
the same version, as an instructor installs the course (docs/classroom.md). Nothing under /root is
opened up.
"""

from __future__ import annotations

import os
import pwd
import stat
import subprocess
import sys
from pathlib import Path

import pytest


def ensure_user(name: str) -> pwd.struct_passwd:
    """The Unix user ``name``, created (no home, no login shell) if it does not exist yet; needs root."""
    try:
        return pwd.getpwnam(name)
    except KeyError:
        subprocess.run(["useradd", "--no-create-home", "--shell", "/usr/sbin/nologin", name], check=True)
        return pwd.getpwnam(name)


def closed_to_others(path: Path) -> str | None:
    """The first directory on the way to ``path`` (symlinks followed) that other users cannot
    enter, or ``path`` itself if they cannot read it; None if the way is open."""
    parts = Path(os.path.realpath(path)).parts
    for depth in range(2, len(parts) + 1):
        step = os.path.join(*parts[:depth])
        mode = os.stat(step).st_mode
        if not mode & (0o001 if stat.S_ISDIR(mode) else 0o004):
            return step
    return None


def shared_venv(workdir: Path) -> Path:
    """A course venv every user can run: this one if it already is, else a hard-linked copy of it
    whose interpreter is the system Python of the same version (as docs/classroom.md installs it)."""
    if closed_to_others(Path(sys.executable)) is None:
        return Path(sys.prefix)
    version = f"python{sys.version_info.major}.{sys.version_info.minor}"
    system_python = Path("/usr/bin") / version
    if not system_python.exists() or closed_to_others(system_python):
        pytest.skip(f"{sys.executable} is closed to other users ({closed_to_others(Path(sys.executable))}) "
                    f"and there is no /usr/bin/{version} to build a shared course venv with")
    venv = workdir / "venv"
    copied = subprocess.run(["cp", "-al", sys.prefix, str(venv)], capture_output=True, text=True)
    if copied.returncode != 0:
        pytest.skip(f"could not hard-link {sys.prefix} into {venv}: {copied.stderr.strip()}")
    # New files only: the links and pyvenv.cfg are replaced, never written through (they are shared).
    for name in ("python", "python3", version):
        (venv / "bin" / name).unlink(missing_ok=True)
        (venv / "bin" / name).symlink_to(system_python)
    (venv / "pyvenv.cfg").unlink()
    (venv / "pyvenv.cfg").write_text(f"home = /usr/bin\ninclude-system-site-packages = false\n"
                                     f"version = {sys.version_info.major}.{sys.version_info.minor}."
                                     f"{sys.version_info.micro}\n")
    return venv
