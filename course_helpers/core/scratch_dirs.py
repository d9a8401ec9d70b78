"""Folders in the temporary directory that belong to one process, and the sweep of those left behind.

A process removes its own folders when it exits normally (``atexit``). A process that is killed
(SIGKILL, an out-of-memory kill, a kernel the server gave up on) cannot: its folders stay. On a
shared JupyterHub that is thousands of folders over a term. So each folder's name carries its
owner, ``<kind>-<pid namespace>-<pid>-<random>``, and making a new folder of a kind first removes
the ones of that kind whose owner is gone.

A folder is removed only when all of these hold:

* it belongs to this Unix user (another student's folders are never touched);
* its pid namespace is this process's (a pid from another container means nothing here);
* no process with its pid exists (a pid reused since is taken as alive: the folder waits for
  that process to end, which is harmless).
"""

from __future__ import annotations

import os
import re
import shutil
import stat
import tempfile

_swept: set[str] = set()  # kinds this process has swept already (once per process is enough)


def _pid_namespace() -> str:
    try:
        return str(os.stat("/proc/self/ns/pid").st_ino)
    except OSError:  # no /proc: no way to tell owners apart, so nothing is ever swept
        return "0"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def _pattern(kind: str) -> re.Pattern:
    return re.compile(rf"{re.escape(kind)}-{_pid_namespace()}-(\d+)-[^/]+\Z")


def sweep(kind: str, parent: str) -> list[str]:
    """Remove this user's ``kind`` folders in ``parent`` whose process is gone; returns those removed."""
    if _pid_namespace() == "0":
        return []
    pattern, removed = _pattern(kind), []
    try:
        names = os.listdir(parent)
    except OSError:
        return []
    for name in names:
        match = pattern.match(name)
        if not match or _alive(int(match.group(1))):
            continue
        path = os.path.join(parent, name)
        try:
            info = os.lstat(path)
        except OSError:  # removed meanwhile
            continue
        if stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid():
            shutil.rmtree(path, ignore_errors=True)
            removed.append(path)
    return removed


def private_dir(kind: str) -> str:
    """A new folder for this process in the temporary directory (mode 0700), named for its owner.

    The first call for a ``kind`` in a process removes that kind's folders that dead processes
    left (:func:`sweep`). The caller still removes its own folder when it exits.
    """
    folder = tempfile.mkdtemp(prefix=f"{kind}-{_pid_namespace()}-{os.getpid()}-")
    if kind not in _swept:
        _swept.add(kind)
        sweep(kind, os.path.dirname(folder))  # the temporary directory, as mkdtemp chose it
    return folder
