"""Benchmark: what the process layer adds to starting and stopping a program, against plain subprocess.

Run with ``.venv/bin/python benchmarks/process_start_cost.py``.

Every program the course runs (build steps, colcon-built nodes, the discovery server) starts
through ``python -m course_helpers.core.child exec``, which stays as the program's supervisor
(``core/supervisor.py``) so that the program's own children stop with it, even when the kernel
is killed. This measures, in one run, alternating:

* run ``true`` to its end: ``subprocess.run`` (the baseline) and ``processes.run``;
* stop a running ``sleep 30`` (started :data:`SETTLE_S` before): ``terminate`` + ``wait`` (the
  baseline) and ``ChildProcess.stop``;
* the memory the course's own process costs while the program runs (unique set size of every
  process of the tree except the program itself: the supervisor; 0 when nothing stays).

It prints medians and the ratio course / baseline.
"""

from __future__ import annotations

import statistics
import subprocess
import time

import psutil

from course_helpers.core import processes

ROUNDS = 15
SETTLE_S = 0.3  # s; a started program is left this long to come up before it is stopped


def _timed(function) -> float:
    started = time.perf_counter()
    function()
    return time.perf_counter() - started


def plain_run() -> None:
    subprocess.run(["true"], check=True)


def course_run() -> None:
    code, _ = processes.run(["true"])
    assert code == 0


def plain_stop() -> float:
    process = subprocess.Popen(["sleep", "30"], start_new_session=True)
    time.sleep(SETTLE_S)
    return _timed(lambda: (process.terminate(), process.wait()))


def course_stop() -> float:
    child = processes.start("bench-sleep", processes.program_argv("sleep", "30"), group="bench",
                            channel=False)
    time.sleep(SETTLE_S)
    return _timed(child.stop)


def supervisor_memory() -> int:
    """Bytes of unique memory of the course's processes around a running ``sleep`` (not the sleep)."""
    child = processes.start("bench-mem", processes.program_argv("sleep", "30"), group="bench", channel=False)
    try:
        tree = [psutil.Process(child.pid), *psutil.Process(child.pid).children(recursive=True)]
        deadline = time.monotonic() + 10
        while not any(p.name() == "sleep" for p in tree) and time.monotonic() < deadline:
            time.sleep(0.01)
            tree = [psutil.Process(child.pid), *psutil.Process(child.pid).children(recursive=True)]
        return sum(p.memory_full_info().uss for p in tree if p.name() != "sleep")
    finally:
        child.stop()


def main() -> None:
    pairs = {"run `true` to its end": (lambda: _timed(plain_run), lambda: _timed(course_run)),
             "stop a running `sleep 30`": (plain_stop, course_stop)}
    for what, (plain, course) in pairs.items():
        plain(), course()  # warm-up
        base, ours = [], []
        for _ in range(ROUNDS):
            base.append(plain())
            ours.append(course())
        b, o = statistics.median(base), statistics.median(ours)
        print(f"{what:<28} plain {b * 1000:7.1f} ms   course {o * 1000:7.1f} ms   ratio {o / b:5.1f}")
    print(f"{'memory beside the program':<28} {supervisor_memory() / 2**20:.1f} MiB (unique set size)")


if __name__ == "__main__":
    main()
