"""Discovery stays fast after a crash: a child started after a killed one is in the kernel's node list
within 0.5 s.

The figure is ``benchmarks/discovery_after_crash.py``'s headline (the course set-up's p90 over 10
children, each started after the one before was killed with SIGKILL): 0.18 s on the 2-core development
machine. Left to Fast DDS, each new child took the killed one's participant id and ports, and its node
was listed only at the next discovery heartbeat, 3.2 s later: the regression this test fails on.

It measures in a fresh process, as a student's kernel starts: Fast DDS reads its profile file once per
process, so a worker whose first participant came from another test's set-up would not measure the
course's.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from course_helpers.core.verdict import judge_timing

# measures time (rates, latencies, DDS events): make test's timing stage, few workers beside it
pytestmark = pytest.mark.timing

BOUND_S = 0.5
RUNS = 10


def _course_times() -> tuple[float, str]:
    """The p90 of the course set-up's times, and every time, sorted (the verdict's line shows them all:
    one slow child of ten is within the bound, two are not)."""
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}  # it reserves a domain of its own
    done = subprocess.run([sys.executable, "-m", "benchmarks.discovery_after_crash", "--course-p90-only",
                           "--runs", str(RUNS)], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    *_, times, p90 = done.stdout.strip().splitlines()
    return float(p90), times


def test_a_child_started_after_a_killed_one_is_seen_within_half_a_second():
    verdict, _ = judge_timing(
        f"a child started after a killed one is in the kernel's node list within {BOUND_S} s (p90 of {RUNS})",
        _course_times, lambda measured: measured[0] <= BOUND_S,
        show=lambda measured: f"p90 {measured[0]:.3f} s (each, in s: {measured[1]})")
    print(verdict.line())
    verdict.raise_unless_passed()
