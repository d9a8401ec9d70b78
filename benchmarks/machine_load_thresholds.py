"""Benchmark: what the load meter reads idle and beside CPU-bound processes (the busy thresholds).

Run with ``.venv/bin/python benchmarks/machine_load_thresholds.py [--runs 3] [--seconds 3]``.

A typical course measurement runs for each setting: a talker in a child process publishes at
200 Hz and the kernel's runtime counts the messages. Meanwhile 0, 1 and 2 CPU-bound processes
(a Python busy loop each) share the machine. For every run the script prints what
:class:`course_helpers.core.machine_load.LoadMeter` read: how long this process tree waited for a
CPU (as a share of the window), the other processes' CPU in cores, and whether it calls the machine
busy. ``MachineLoad.busy`` must be False in every idle run and True in every loaded one; the
script exits 1 otherwise, so the thresholds in ``core/machine_load.py`` follow the measurement.
"""

from __future__ import annotations

import argparse
import sys
import time

from std_msgs.msg import String

from course_helpers.core.machine_load import BUSY_CORES, STARVED_SHARE, LoadMeter
from course_helpers.core.runtime import get_runtime
from course_helpers.nodes.chatter import Talker
from tools.busy_loops import busy_loops


def _measure(rt, seconds: float) -> tuple:
    """One window of the typical measurement; (the load it met, messages counted)."""
    received: list = []
    node = rt.node("load_probe")
    node.create_subscription(String, "load_chatter", received.append, 100)
    rt.spawn("load_talker", Talker, params={"topic": "load_chatter", "rate_hz": 200.0},
             wait_for="/talker")
    meter = LoadMeter()
    time.sleep(seconds)  # the window is the measurement itself: it runs for a fixed time
    load = meter.finish()
    rt.stop_child("load_talker")
    rt.remove(node)
    return load, len(received)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=3, help="runs per setting (default 3)")
    parser.add_argument("--seconds", type=float, default=3.0, help="length of each window (default 3 s)")
    args = parser.parse_args(argv)
    rt = get_runtime()
    wrong = 0
    print(f"thresholds: busy when starved >= {STARVED_SHARE:.0%} or others >= {BUSY_CORES} cores")
    print(f"{'busy loops':>10} {'starved':>8} {'others (cores)':>15} {'messages':>9}  busy?")
    for hogs in (0, 1, 2):
        with busy_loops(hogs):
            for _ in range(args.runs):
                load, count = _measure(rt, args.seconds)
                expected = hogs > 0
                wrong += load.busy != expected
                print(f"{hogs:>10} {load.starved_share:>8.0%} {load.others_cores:>15.2f} {count:>9}  "
                      f"{'yes' if load.busy else 'no'}{'' if load.busy == expected else '  <- wrong'}")
    rt.stop()
    print("every reading as expected" if not wrong else f"{wrong} reading(s) not as expected")
    return 1 if wrong else 0


if __name__ == "__main__":
    sys.exit(main())
