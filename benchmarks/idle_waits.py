"""Benchmark: the CPU a kernel spends while it waits, against the same kernel idle.

Run with ``.venv/bin/python benchmarks/idle_waits.py``.

Each measurement runs in a fresh Python process: a course runtime with a graph of
``GRAPH_NODES`` child-process talkers (plus the kernel's own listener), as a chapter has. It then
measures the process's CPU time (every thread) over ``WAIT_S`` seconds of

* nothing (the baseline: the executor spinning an idle listener, the talkers' messages arriving);
* ``rt.wait_until`` for a node that never appears (the usual graph wait, which times out);
* ``waiting.wait_until`` on a plain condition that never comes true;
* ``rt.spawn(..., wait_for=...)`` of a child that takes ``WAIT_S`` seconds before its node exists.

It prints each one's CPU as a percentage of one core and the ratio to the baseline. Run it before
and after a change to the waits: the numbers are only comparable within one run on one machine.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

GRAPH_NODES = 6
WAIT_S = 10.0

MEASURE = """
import json, sys, threading, time
from course_helpers import get_runtime, WaitTimeout
from course_helpers.core import waiting
from course_helpers.nodes import Listener, make_talker

case, nodes, wait_s = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
rt = get_runtime()
rt.add(Listener, console=False)
for i in range(nodes):
    rt.spawn(f"bench_talker_{i}", make_talker, params={"name": f"bench_talker_{i}", "rate_hz": 2.0},
             wait_for=f"/bench_talker_{i}")
time.sleep(1.0)  # discovery settles
started, cpu = time.monotonic(), time.process_time()
if case == "idle":
    time.sleep(wait_s)
elif case == "rt.wait_until(graph)":
    try:
        rt.wait_until(lambda: "/never" in rt.graph_nodes(), wait_s, "a node that never comes")
    except WaitTimeout:
        pass
elif case == "waiting.wait_until(plain)":
    flag = threading.Event()
    try:
        waiting.wait_until(flag.is_set, wait_s, "a flag that is never set")
    except WaitTimeout:
        pass
elif case == "rt.spawn(wait_for=...)":
    rt.spawn("late", "benchmarks.idle_waits:late_talker", params={"delay_s": wait_s}, wait_for="/late",
             timeout=wait_s + 20)
cpu, wall = time.process_time() - cpu, time.monotonic() - started
print(json.dumps({"cpu": cpu, "wall": wall}))
"""
CASES = ("idle", "rt.wait_until(graph)", "waiting.wait_until(plain)", "rt.spawn(wait_for=...)")


def late_talker(delay_s: float = WAIT_S):
    """A child target whose node exists only ``delay_s`` seconds after the process starts."""
    import time

    from course_helpers.nodes import Talker

    time.sleep(delay_s)
    return Talker(name="late")


def measure(case: str) -> dict:
    argv = [sys.executable, "-c", textwrap.dedent(MEASURE), case, str(GRAPH_NODES), str(WAIT_S)]
    out = subprocess.run(argv, capture_output=True, text=True, timeout=300, cwd=_repo())
    if out.returncode != 0:
        raise RuntimeError(f"{case} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _repo() -> str:
    return os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main() -> None:
    results = {case: measure(case) for case in CASES}
    base = results["idle"]["cpu"] / results["idle"]["wall"]
    print(f"{GRAPH_NODES} child talkers in the graph; CPU of the kernel process, % of one core over "
          f"about {WAIT_S:g} s")
    for case, r in results.items():
        share = r["cpu"] / r["wall"]
        print(f"{case:<28} {100 * share:6.2f} %   ratio to idle {share / base:5.2f}   ({r['wall']:.1f} s)")


if __name__ == "__main__":
    main()
