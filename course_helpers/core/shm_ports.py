"""Leftover Fast DDS shared-memory files: stale ports of a domain the course reserves, and dead segments.

Fast DDS keeps each participant's shared memory in ``/dev/shm``: a segment (``fastrtps_<16 hex>``)
and a listening port per locator (``fastrtps_port<number>``, where the number is the RTPS port:
7400 + 250 x domain + ...). A live owner holds an ``flock`` on the file's ``_el`` companion.

* **A port outlives its listener** while any other process still has it open for writing, and for
  ever if that process was killed. The next participant that gets the same port number opens the
  old port as it is, with the health-check timeout of whoever created it (:mod:`.dds_config`
  explains why that timeout matters). When the course reserves a domain, no course participant uses
  it, so :func:`remove_stale_ports` deletes that domain's ports that have no listener.
* **A killed process leaves its segment** (about 0.5 MB of memory each). :func:`remove_dead_segments`
  deletes the segments whose ``_el`` lock nobody holds, the rule of ``fastdds shm clean``.

Left alone: the files of other Unix users (they cannot be deleted), and the ports of the graph
readers (7000-7399, one range for the whole machine): a live process in any domain may still write
to such a port, and would keep writing into the deleted copy after a new listener made a fresh one.
"""

from __future__ import annotations

import fcntl
import os
import re

SHM_DIR = "/dev/shm"
PORTS_PER_DOMAIN = 250  # the RTPS port mapping: 7400 + 250 x domain + offsets
_PORT = re.compile(r"fastrtps_port(\d+)")
_SEGMENT = re.compile(r"fastrtps_[0-9a-f]{16}")


def port_number(name: str) -> int | None:
    """The RTPS port of a port file's name (``fastrtps_port7410`` gives 7410); None for any other name."""
    match = _PORT.fullmatch(name)
    return int(match.group(1)) if match else None


def _held(lock_path: str) -> bool:
    """True if a process holds an flock on ``lock_path`` (a live owner of the Fast DDS object)."""
    try:
        fd = os.open(lock_path, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    else:
        fcntl.flock(fd, fcntl.LOCK_UN)
        return False
    finally:
        os.close(fd)


def _remove(names: list[str]) -> bool:
    """Delete ``names`` from /dev/shm; True if the first (the object itself) was deleted."""
    deleted = []
    for name in names:
        try:
            os.remove(os.path.join(SHM_DIR, name))
            deleted.append(name)
        except OSError:
            pass  # gone already, or another user's
    return names[0] in deleted


def remove_stale_ports(domain: int) -> int:
    """Delete the shared-memory ports of ``domain`` that no process listens on; return how many.

    Call it only for a domain the course has just reserved, before any participant uses it.
    """
    first = 7400 + PORTS_PER_DOMAIN * domain
    removed = 0
    for name in _listing():
        port = port_number(name)
        if port is None or not first <= port < first + PORTS_PER_DOMAIN:
            continue
        base = os.path.join(SHM_DIR, name)
        if _held(base + "_el") or _held(base + "_sl"):
            continue
        removed += _remove([name, name + "_el", name + "_sl", f"sem.{name}_mutex"])
    return removed


def remove_dead_segments() -> int:
    """Delete the segments of participants whose process is gone (``_el`` lock free); return how many."""
    removed = 0
    for name in _listing():
        if _SEGMENT.fullmatch(name) and os.path.exists(os.path.join(SHM_DIR, name + "_el")):
            if not _held(os.path.join(SHM_DIR, name + "_el")):
                removed += _remove([name, name + "_el", f"sem.{name}_mutex"])
    return removed


def _listing() -> list[str]:
    try:
        return os.listdir(SHM_DIR)
    except OSError:
        return []
