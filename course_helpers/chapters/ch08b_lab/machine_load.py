"""How busy the machine was during a QoS lab run: :class:`LoadMeter` and :class:`MachineLoad`.

A lab run measures what one machine delivers, so its numbers change when other work shares
the CPU. The meter records, over a run,

* the CPU time every **other** process used (the machine's busy time minus this kernel's own,
  its reaped child processes included), in cores: 1.0 is one core kept busy the whole run;
* the 1-minute load average per core at the end;
* the **other course kernels of this user**, of any Jupyter server or test process on the
  machine, and their child processes (:func:`course_helpers.core.other_kernels.other_kernels`,
  machine-wide). This kernel and its own children are left out.

``MachineLoad.busy`` is True when other processes kept at least ``BUSY_CORES`` cores busy, or the
load average is at least ``BUSY_LOAD_PER_CORE`` per core; ``describe()`` says so in one line, with
what a student can do about it.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import psutil

from course_helpers.core.other_kernels import other_kernels

BUSY_CORES = 0.5  # other processes used at least half a core on average during the run
BUSY_LOAD_PER_CORE = 1.0  # or more runnable processes than cores, over the last minute


@dataclass(frozen=True)
class MachineLoad:
    """What shared the machine with one run (see the module docstring)."""

    cores: int
    seconds: float  # the run's wall time over which ``others_cores`` was measured
    others_cores: float  # CPU time of every other process / seconds (1.0 = one core busy)
    load_per_core: float  # 1-minute load average / cores, at the end of the run
    kernels: tuple[int, ...] = ()  # PIDs of other course kernels of this user (holding a course domain)
    children: tuple[int, ...] = ()  # PIDs of other course kernels' child processes

    @property
    def busy(self) -> bool:
        """True when other work had a real share of the CPU during the run."""
        return self.others_cores >= BUSY_CORES or self.load_per_core >= BUSY_LOAD_PER_CORE

    def describe(self) -> str:
        """One line: how busy the machine was, what else of the course runs, and what to do."""
        course = _course_processes(len(self.kernels), len(self.children))
        if not self.busy:
            line = (f"The machine was quiet during this run: other processes used {self.others_cores:.1f} "
                    f"of its {self.cores} cores.")
            return line + (f" Also running: {course}." if course else "")
        line = (f"This machine was busy during the run: other processes used {self.others_cores:.1f} of its "
                f"{self.cores} cores (load average {self.load_per_core:.1f} per core)")
        if course:
            line += f"; {course} are running"
        line += (". Timing and delivery under load depend on that: for numbers of a quiet machine, shut "
                 "down the kernels of other notebooks (JupyterLab's Running panel) and run again.")
        return line


def _course_processes(kernels: int, children: int) -> str:
    parts = []
    if kernels:
        parts.append(f"{kernels} other course kernel{'s' if kernels != 1 else ''} (or test process"
                     f"{'es' if kernels != 1 else ''})")
    if children:
        parts.append(f"{children} child process{'es' if children != 1 else ''} of other course kernels")
    return " and ".join(parts)


class LoadMeter:
    """``meter = LoadMeter()`` when a run starts, ``meter.finish()`` when it ends: a MachineLoad."""

    def __init__(self):
        self.started = time.monotonic()
        self._busy0 = _machine_busy_seconds()
        self._own0 = _own_seconds()

    def finish(self) -> MachineLoad:
        seconds = max(time.monotonic() - self.started, 1e-3)
        others = max(0.0, (_machine_busy_seconds() - self._busy0) - (_own_seconds() - self._own0))
        cores = psutil.cpu_count() or 1
        kernels = other_kernels(machine_wide=True)  # of every Jupyter server: all compete for the CPU
        return MachineLoad(cores=cores, seconds=seconds, others_cores=others / seconds,
                           load_per_core=os.getloadavg()[0] / cores,
                           kernels=tuple(kernel.pid for kernel in kernels),
                           children=tuple(sorted(pid for kernel in kernels for pid in kernel.children)))


def _machine_busy_seconds() -> float:
    """CPU seconds every core spent on anything but idling, since boot."""
    times = psutil.cpu_times()
    return sum(times) - times.idle - getattr(times, "iowait", 0.0)


def _own_seconds() -> float:
    """CPU seconds of this process, its threads and its reaped children."""
    times = psutil.Process().cpu_times()
    return times.user + times.system + times.children_user + times.children_system
