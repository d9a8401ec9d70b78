"""Discovery stays fast after a crash: a child started after a killed one is in the kernel's node list
within 0.5 s, for the median child of 10.

The figures are ``benchmarks/discovery_after_crash.py``'s (each child started after the one before was
killed with SIGKILL): course p50 0.16-0.2 s and p90 about 0.2 s on the 2-core development machine. Left
to Fast DDS, each new child took the killed one's participant id and ports, and every child's node was
listed only at the next discovery heartbeat, 3.2 s later: the regression this test fails on.

Why the median and not the p90: about one child in 60 to 130 is listed after 0.8 s or 1.9 s, on an idle
machine, with the course's slots, while the child itself lists the kernel's node within 10 ms. The
likeliest cause (not traced on the wire): one of the child's endpoint announcements (SEDP) is lost, and
Fast DDS repairs it at its next endpoint-discovery heartbeat, a fixed 1 s (``edp_heartbeat_period`` in
``EDPSimple.cpp``, which no profile sets); a 0.05 s heartbeat on the graph topic's writer changed nothing.
Two such children in ten make a p90 of 0.8 s, so a p90 bound would fail about one run in a hundred
through no fault of the course. The median fails only if five of ten children wait, and fails at once
on the regression. The verdict's line shows every child's time.

It measures in a fresh process, as a student's kernel starts: Fast DDS reads its profile file once per
process, so a worker whose first participant came from another test's set-up would not measure the
course's.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys

import pytest

from course_helpers.core.verdict import judge_timing

# measures time (rates, latencies, DDS events): make test's timing stage, few workers beside it
pytestmark = pytest.mark.timing

BOUND_S = 0.5
RUNS = 10


def _course_times() -> list[float]:
    """The seconds until the kernel listed each of RUNS children, each started after a killed one."""
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}  # it reserves a domain of its own
    done = subprocess.run([sys.executable, "-m", "benchmarks.discovery_after_crash", "--course-times",
                           "--runs", str(RUNS)], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return [float(value) for value in done.stdout.strip().splitlines()[-1].split()]


def test_a_child_started_after_a_killed_one_is_seen_within_half_a_second():
    verdict, _ = judge_timing(
        f"a child started after a killed one is in the kernel's node list within {BOUND_S} s "
        f"(median of {RUNS})",
        _course_times, lambda times: statistics.median(times) <= BOUND_S,
        show=lambda times: f"median {statistics.median(times):.3f} s; each, in s: "
                           + " ".join(f"{value:.3f}" for value in times))
    print(verdict.line())
    verdict.raise_unless_passed()
