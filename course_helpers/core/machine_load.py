"""How busy the machine was while something was measured: :class:`LoadMeter` and :class:`MachineLoad`.

A timing measurement (a latency, a rate, a discovery time) tells how fast this machine did the work
only if the work got the CPU when it asked for it. The meter records, over a window, two readings
that say whether it did:

* **starvation**: how long the threads of this process and of its child processes were ready to run
  but waited for a CPU (the kernel's scheduler statistics, ``/proc/<pid>/task/<tid>/schedstat``), as a
  share of the window. 0.25 means that, on average, a quarter of a thread was kept waiting all along.
  This is the reading that decides: a measurement that was not starved is a measurement of the work.
* **other processes' CPU**: the machine's busy time minus this process tree's own, in cores (1.0 is
  one core kept busy for the whole window). It names the cause.

It also lists the **other course kernels of this user** (:mod:`.other_kernels`, machine-wide): the
likeliest cause on a student's machine, and one a student can end.

``MachineLoad.busy`` is True when this process tree waited for a CPU for at least
:data:`STARVED_SHARE` of the window, or other processes used at least :data:`BUSY_CORES` cores. Both
thresholds follow measurements on the 2-core development machine, which
``benchmarks/machine_load_thresholds.py`` repeats (a kernel counting a child talker's 200 Hz for 3 s):
idle, the tree waited 3-4 % of the window and others used 0.0-0.1 cores; beside one CPU-bound
process 9-11 % and 0.9-1.05 cores; beside two 9-11 % and 1.9 cores. A tree that mostly sleeps is
seldom kept waiting, so the other processes' CPU is the reading that tells a loaded machine; the
starvation tells a measurement whose own threads had to queue (a heavy one, or one core).
The 1-minute load average is reported, never judged: it lags a short window by a minute.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import psutil

from course_helpers.core.other_kernels import other_kernels

STARVED_SHARE = 0.15  # this process tree waited for a CPU at least this share of the window
BUSY_CORES = 0.5  # or other processes kept at least half a core busy on average


@dataclass(frozen=True)
class MachineLoad:
    """What shared the machine with one measurement (see the module docstring)."""

    cores: int
    seconds: float  # the window's wall time
    others_cores: float  # CPU time of every process outside this tree / seconds (1.0 = one core busy)
    load_per_core: float  # 1-minute load average / cores, at the end (reported only)
    starved_share: float = 0.0  # time this tree's threads waited for a CPU / seconds
    own_cores: float = 0.0  # CPU time of this process and its children / seconds
    kernels: tuple[int, ...] = ()  # PIDs of other course kernels of this user (holding a course domain)
    children: tuple[int, ...] = ()  # PIDs of other course kernels' child processes

    @property
    def busy(self) -> bool:
        """True when the measurement had to share the CPU (see the module docstring)."""
        return self.starved_share >= STARVED_SHARE or self.others_cores >= BUSY_CORES

    def reading(self) -> str:
        """The numbers in a few words: 'other processes used 1.3 of 2 cores; this one waited 41% ...'."""
        return (f"other processes used {self.others_cores:.1f} of {self.cores} cores, and this one waited "
                f"for a CPU {self.starved_share:.0%} of the {self.seconds:.1f} s")

    def course_processes(self) -> str:
        """'2 other course kernels and 3 child processes of other course kernels', or ''."""
        parts = []
        kernels, children = len(self.kernels), len(self.children)
        if kernels:
            parts.append(f"{kernels} other course kernel{'s' if kernels != 1 else ''}")
        if children:
            parts.append(f"{children} child process{'es' if children != 1 else ''} of other course kernels")
        return " and ".join(parts)

    def advice(self) -> str:
        """What a student can do about a busy machine, in one sentence."""
        if self.kernels or self.children:
            return ("shut down the other notebooks' kernels (rt.shutdown_other_kernels(), or JupyterLab's "
                    "Running panel) and run it again")
        return "close what else keeps the CPU busy and run it again"

    def describe(self) -> str:
        """One line: how busy the machine was, what else of the course runs, and what to do."""
        course = self.course_processes()
        if not self.busy:
            line = f"The machine was quiet during this run: {self.reading()}."
            return line + (f" Also running: {course}." if course else "")
        line = f"This machine was busy during the run: {self.reading()}"
        if course:
            verb = "is" if len(self.kernels) + len(self.children) == 1 else "are"
            line += f"; {course} {verb} running"
        return line + (f". Timing under load depends on that: for the numbers of a quiet machine, "
                       f"{self.advice()}.")


class LoadMeter:
    """``meter = LoadMeter()`` when a window starts, ``meter.finish()`` when it ends: a MachineLoad."""

    def __init__(self):
        self.started = time.monotonic()
        self._busy0 = _machine_busy_seconds()
        self._tree0 = _tree_readings()

    def finish(self, course_kernels: bool = True) -> MachineLoad:
        """The load over the window. ``course_kernels=False`` skips the search for other course kernels
        (it costs a few milliseconds per process of the user)."""
        seconds = max(time.monotonic() - self.started, 1e-3)
        tree1 = _tree_readings()
        own = _delta(self._tree0, tree1, 0) + _own_reaped_seconds() - self._tree0["reaped"]
        waited = _delta(self._tree0, tree1, 1)
        others = max(0.0, (_machine_busy_seconds() - self._busy0) - own)
        cores = psutil.cpu_count() or 1
        kernels = other_kernels(machine_wide=True) if course_kernels else []
        return MachineLoad(cores=cores, seconds=seconds, others_cores=others / seconds,
                           load_per_core=os.getloadavg()[0] / cores, starved_share=waited / seconds,
                           own_cores=own / seconds,
                           kernels=tuple(kernel.pid for kernel in kernels),
                           children=tuple(sorted(pid for kernel in kernels for pid in kernel.children)))


def cpu_seconds(pid: int) -> float | None:
    """The CPU time process ``pid`` has used so far (user and system), or None if it has ended."""
    try:
        times = psutil.Process(pid).cpu_times()
    except psutil.Error:
        return None
    return times.user + times.system


def _machine_busy_seconds() -> float:
    """CPU seconds every core spent on anything but idling, since boot."""
    times = psutil.cpu_times()
    return sum(times) - times.idle - getattr(times, "iowait", 0.0)


def _own_reaped_seconds() -> float:
    """CPU seconds of the children this process has reaped."""
    times = os.times()
    return times.children_user + times.children_system


def _tree_readings() -> dict:
    """Per thread of this process and its descendants: (CPU seconds, seconds waited for a CPU), keyed
    by (pid, tid, the thread's start in clock ticks) so that a reused id is not mistaken for its
    predecessor; and the CPU of this process's reaped children under ``'reaped'``."""
    readings: dict = {"reaped": _own_reaped_seconds()}
    me = psutil.Process()
    try:
        pids = [me.pid, *(child.pid for child in me.children(recursive=True))]
    except psutil.Error:
        pids = [me.pid]
    for pid in pids:
        try:
            tids = os.listdir(f"/proc/{pid}/task")
        except OSError:
            continue
        for tid in tids:
            reading = _thread_reading(pid, tid)
            if reading is not None:
                readings[(pid, tid, reading[0])] = reading[1:]
    return readings


def _thread_reading(pid: int, tid: str) -> tuple[int, float, float] | None:
    """(start ticks, CPU seconds, seconds waited runnable) of one thread, or None if it is gone."""
    try:
        with open(f"/proc/{pid}/task/{tid}/schedstat", encoding="ascii") as handle:
            ran_ns, waited_ns, _slices = handle.read().split()
        with open(f"/proc/{pid}/task/{tid}/stat", encoding="ascii") as handle:
            start_ticks = int(handle.read().rsplit(")", 1)[1].split()[19])
    except (OSError, ValueError, IndexError):
        return None
    return start_ticks, int(ran_ns) / 1e9, int(waited_ns) / 1e9


def _delta(before: dict, after: dict, field: int) -> float:
    """Sum over the threads alive at the end of what they added since the start (all of it for a
    thread that started meanwhile)."""
    total = 0.0
    for key, values in after.items():
        if key == "reaped":
            continue
        earlier = before.get(key)
        total += values[field] - (earlier[field] if earlier is not None else 0.0)
    return max(0.0, total)
