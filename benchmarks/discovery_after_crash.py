"""Benchmark: how fast the kernel finds a new child's node when the child before it crashed.

Run with ``.venv/bin/python benchmarks/discovery_after_crash.py [--runs 20]``.

A child that is killed (or crashes) leaves its shared-memory ports with its listener registered, and
the kernel keeps them open. Left to Fast DDS, the next child takes the same participant id and ports,
and what the kernel sends it before its port watchdog gives up on the old port is lost: the node is
found at the next discovery heartbeat, 3 s later. The course gives each child a port slot of its own
(``course_helpers/core/port_slots.py``).

Two set-ups in one course runtime, one after the other (the crashed children of the second would
otherwise leave stale ports on slots the first has not used yet):

* ``course``: children started through the process layer as the course starts them (a port slot each);
* ``fastdds-choice``: the same, with the slots switched off, so Fast DDS picks the participant id (the
  lowest free one: the crashed child's).

Each round starts a child that makes one node and reports, and times from that report until the
kernel's graph lists the node; then the child is killed with SIGKILL. Prints p50, p90 and the
slowest time per set-up, how many took a second or more, and the ratio of the two p90s.
"""

from __future__ import annotations

import argparse
import statistics
import time
from contextlib import contextmanager

from benchmarks.discovery_targets import named_node_procedure
from course_helpers.core import port_slots
from course_helpers.core.runtime import get_runtime
from course_helpers.core.waiting import poll_until

SETUPS = ("course", "fastdds-choice")
TIMEOUT_S = 10.0  # s; a node not found by then counts as this long (more than three heartbeats)


@contextmanager
def _slots(setup: str):
    """While a child of ``setup`` starts: the course's slots, or none (Fast DDS's own choice)."""
    original = port_slots.take
    if setup == "fastdds-choice":
        port_slots.take = lambda *_args: None
    try:
        yield
    finally:
        port_slots.take = original


def one_round(rt, setup: str, index: int) -> float:
    """Start a child (after the previous one was killed), time until the kernel lists its node, kill it."""
    label = f"crash_probe_{setup.replace('-', '_')}"
    name = f"{label}_{index}"  # a killed child stays in the graph for its lease: never reuse a name
    with _slots(setup):
        child = rt.spawn(label, named_node_procedure, {"name": name})
    child.wait_for_report("ready", 30, f"child {name} to make its node")
    started = time.monotonic()
    found = poll_until(lambda: f"/{name}" in rt.graph_nodes(), TIMEOUT_S)
    took = time.monotonic() - started if found else TIMEOUT_S
    child.kill()  # SIGKILL: no goodbye, as a crash
    return took


def measure(runs: int) -> dict[str, list[float]]:
    """Seconds until the kernel listed each new child's node, per set-up; each child follows a killed
    one of its set-up (one child more than ``runs`` per set-up: the first only warms up)."""
    rt = get_runtime()
    return {setup: [one_round(rt, setup, index) for index in range(runs + 1)][1:] for setup in SETUPS}


def p90(values: list[float]) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(0.9 * (len(ordered) - 1)))]


def course_after_crash(runs: int = 10) -> list[float]:
    """The course set-up's times alone (the regression test's figures): each child follows a killed one."""
    rt = get_runtime()
    return [one_round(rt, "course", index) for index in range(runs + 1)][1:]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20, help="children per set-up (default 20)")
    parser.add_argument("--course-times", action="store_true",
                        help="only the course set-up's times over --runs children, sorted (for the test)")
    args = parser.parse_args()
    if args.course_times:
        print(" ".join(f"{value:.3f}" for value in sorted(course_after_crash(args.runs))))
        return
    times = measure(args.runs)
    print(f"a new child after a killed one: seconds until the kernel lists its node ({args.runs} per set-up)")
    print(f"{'set-up':16} {'p50':>7} {'p90':>7} {'slowest':>8} {'>= 1 s':>7}")
    for setup, values in times.items():
        slow = sum(1 for v in values if v >= 1.0)
        print(f"{setup:16} {statistics.median(values):7.3f} {p90(values):7.3f} {max(values):8.3f} "
              f"{slow:>4}/{len(values)}")
    ratio = p90(times["course"]) / p90(times["fastdds-choice"])
    print(f"course p90 / fastdds-choice p90: {ratio:.2f}")


if __name__ == "__main__":
    main()
