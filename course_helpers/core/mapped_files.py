"""The files mapped into a process's memory (read with psutil): its shared libraries, and Fast DDS's
shared-memory files.

Fast DDS keeps each participant's shared memory in ``/dev/shm``: a segment holding what it sends
(``fastrtps_<16 hex>``) and a receive queue per listening port (``fastrtps_port<number>``). A process
maps its own participants' files, and the segments and ports of the peers it exchanges data with.
"""

from __future__ import annotations

import os

from course_helpers.core.errors import CourseError

FAST_DDS_SHM = "/dev/shm/fast"  # fastrtps_* and fastdds_* files


def mapped_files(pid: int | str = "self") -> list[str]:
    """The paths of the files mapped into process ``pid`` ('self': this one), each once."""
    import psutil

    try:
        process = psutil.Process() if pid == "self" else psutil.Process(int(pid))
        return [region.path for region in process.memory_maps(grouped=True)]
    except (psutil.Error, ValueError) as exc:
        raise CourseError(f"cannot read the memory maps of process {pid} ({exc}); this needs Linux "
                          "and a process of your own") from None


def shm_files(pid: int | str = "self") -> list[str]:
    """The basenames of the Fast DDS shared-memory files mapped into process ``pid``, sorted."""
    return sorted({os.path.basename(path) for path in mapped_files(pid) if path.startswith(FAST_DDS_SHM)})


def replaced_shm_ports(pid: int | str = "self") -> list[str]:
    """The Fast DDS shared-memory ports mapped into process ``pid`` whose file is gone from ``/dev/shm``
    or is another file now (another process removed it and made a new one), sorted.

    A participant listening on such a port no longer hears the processes that open the port after it
    was replaced: they write into the new file."""
    replaced = set()
    try:
        with open(f"/proc/{pid}/maps", encoding="utf-8", errors="replace") as maps:
            for line in maps:
                fields = line.split(maxsplit=5)
                if len(fields) < 6 or not fields[5].startswith(FAST_DDS_SHM + "rtps_port"):
                    continue
                path = fields[5].strip().removesuffix(" (deleted)")
                try:
                    current = os.stat(path).st_ino
                except OSError:
                    current = None
                if current != int(fields[4]):
                    replaced.add(os.path.basename(path))
    except OSError:
        return []
    return sorted(replaced)
