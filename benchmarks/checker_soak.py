"""Soak: every exercise checker against its reference solution, N times, beside K busy processes.

Run ``.venv/bin/python -m benchmarks.checker_soak --runs 10 --busy 2`` from the repository root (``--only
ch08`` for the checkers whose name holds ch08). Each run checks every reference once in this process,
with one course runtime, as a student's kernel would. The busy processes (:mod:`tools.busy_loops`) are
real CPU-bound neighbours outside this process tree.

A reference must pass every time: a criterion it fails is a checker bug, and an inconclusive one (a
timing criterion still missed after its retries on a busy machine) counts as not passed. Prints each
check as it ends, then per checker the passes, the inconclusive runs, the median and slowest seconds,
and every criterion that did not pass, with its detail. Exits 1 unless every check of every run passed.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable

from course_helpers.checks.ch01_architecture import check_silence_watchdog
from course_helpers.checks.ch02_executors import check_responsive_robot
from course_helpers.checks.ch03_topics import check_cmd_vel_logger, check_throughput, check_tilt_warning
from course_helpers.checks.ch03b_bags import check_odom_monitor
from course_helpers.checks.ch04_services import check_battery_server, check_relay_server
from course_helpers.checks.ch05_actions import check_navigation_server
from course_helpers.checks.ch06_parameters import check_conveyor_launch, check_overheat_monitor
from course_helpers.checks.ch07_dds import check_private_robot
from course_helpers.checks.ch08_qos import check_channel_qos, check_mismatched_subscriber
from course_helpers.checks.ch08_qos_events import check_deadline_watchdog, check_heartbeat
from course_helpers.checks.ch08b_lab import check_burst_qos
from course_helpers.checks.ch09_packages import check_package
from course_helpers.checks.ch10_capstone import check_fleet_estop
from course_helpers.core.runtime import get_runtime
from course_helpers.solutions import (
    ch01_architecture,
    ch02_executors,
    ch03_topics,
    ch03b_bags,
    ch04_services,
    ch05_actions,
    ch06_parameters,
    ch07_dds,
    ch08_qos,
    ch08_qos_events,
    ch08b_lab,
    ch09_packages,
    ch10_capstone,
)
from tools.busy_loops import busy_loops

# Every exercise checker with its reference, called as the notebooks' "what passing looks like" cells do.
REFERENCES: dict[str, Callable] = {
    "ch01 silence watchdog": lambda: check_silence_watchdog(ch01_architecture.SilenceWatchdog),
    "ch02 responsive robot": lambda: check_responsive_robot(ch02_executors.Robot),
    "ch03 tilt warning": lambda: check_tilt_warning(ch03_topics.TiltMonitor),
    "ch03 cmd_vel logger": lambda: check_cmd_vel_logger(ch03_topics.CmdVelCsvLogger),
    "ch03 throughput": lambda: check_throughput(ch03_topics.ThroughputSolution.expected_load,
                                                ch03_topics.ThroughputSolution.measure_load),
    "ch03b odometry monitor": lambda: check_odom_monitor(ch03b_bags.OdomMonitor),
    "ch04 battery server": lambda: check_battery_server(ch04_services.BatteryMonitor),
    "ch04 relay server": lambda: check_relay_server(ch04_services.SumRelay),
    "ch05 navigation server": lambda: check_navigation_server(ch05_actions.NavigationServer),
    "ch06 overheat monitor": lambda: check_overheat_monitor(ch06_parameters.OverheatMonitor),
    "ch06 conveyor launch": lambda: check_conveyor_launch(ch06_parameters.ConveyorLaunchTest.describe,
                                                          ch06_parameters.ConveyorLaunchTest.proves_they_talk),
    "ch07 private robot": lambda: check_private_robot(ch07_dds.PrivateRobot, ch07_dds.private_context),
    "ch08 channel QoS": lambda: check_channel_qos(ch08_qos.channel_qos()),
    "ch08 mismatched subscriber": lambda: check_mismatched_subscriber(ch08_qos.RobotCmdListener),
    "ch08 deadline watchdog": lambda: check_deadline_watchdog(ch08_qos_events.OdomWatchdog),
    "ch08 heartbeat": lambda: check_heartbeat(*ch08_qos_events.heartbeat_nodes()),
    "ch08b burst QoS": lambda: check_burst_qos(ch08b_lab.burst_qos()),
    "ch09 package": lambda: check_package(ch09_packages.reference_package()),
    "ch10 fleet e-stop": lambda: check_fleet_estop(ch10_capstone.FleetSafetyMonitor),
}


def run_check(name: str) -> tuple[str, float, list[str]]:
    """('pass' | 'inconclusive' | 'fail', seconds, the criteria that did not pass) of one check."""
    started = time.monotonic()
    try:
        report = REFERENCES[name]()
    except Exception as exc:  # a checker that raises is a failure of the checker
        return "fail", time.monotonic() - started, [f"raised {type(exc).__name__}: {exc}"]
    seconds = time.monotonic() - started
    missed = [c for c in report.criteria if not c.passed]
    lines = [f"[{c.tag}] {c.name}" + (f" - {c.detail}" if c.detail else "") for c in missed]
    if not missed:
        return "pass", seconds, []
    return ("inconclusive" if all(c.inconclusive for c in missed) else "fail"), seconds, lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Every reference, N times, beside K busy processes.")
    parser.add_argument("--runs", type=int, default=10, help="runs of every check (1-50, default 10)")
    parser.add_argument("--busy", type=int, default=2, help="CPU-bound neighbours (0-16, default 2)")
    parser.add_argument("--only", default="", help="only the checkers whose name contains this text")
    args = parser.parse_args(argv)
    if not 1 <= args.runs <= 50:
        parser.error(f"--runs must be 1..50, got {args.runs}")
    if not 0 <= args.busy <= 16:
        parser.error(f"--busy must be 0..16, got {args.busy}")
    names = [name for name in REFERENCES if args.only in name]
    if not names:
        parser.error(f"no checker's name contains {args.only!r}; the names are: {', '.join(REFERENCES)}")
    get_runtime()
    results: dict[str, list[tuple[str, float, list[str]]]] = {name: [] for name in names}
    with busy_loops(args.busy):
        print(f"checker soak: {len(names)} checker(s), {args.runs} run(s), beside {args.busy} busy "
              "process(es)", flush=True)
        for run in range(1, args.runs + 1):
            for name in names:
                outcome, seconds, lines = run_check(name)
                results[name].append((outcome, seconds, lines))
                print(f"run {run}/{args.runs} {name}: {outcome} in {seconds:.1f} s", flush=True)
                for line in lines:
                    print(f"    {line}", flush=True)
    print(f"\n{'checker':<28} passed  inconclusive  median  slowest")
    for name, runs in results.items():
        times = [seconds for _outcome, seconds, _lines in runs]
        print(f"{name:<28} {sum(o == 'pass' for o, _s, _l in runs):>3}/{len(runs):<3} "
              f"{sum(o == 'inconclusive' for o, _s, _l in runs):>12}  {statistics.median(times):5.1f} s "
              f"{max(times):6.1f} s")
    return 0 if all(o == "pass" for runs in results.values() for o, _s, _l in runs) else 1


if __name__ == "__main__":
    sys.exit(main())
