"""Soak: the stages of ``make test`` N times, optionally beside K CPU-bound processes.

Run ``make soak RUNS=5 BUSY=1`` (or ``.venv/bin/python -m benchmarks.soak --runs 5 --busy 1``) from the
repository root. Each run is ``make logic``, ``make timing`` and ``make notebooks``, the same commands,
workers and timeouts as ``make test``, one after the other (``--stages`` picks some). The busy
processes (:mod:`tools.busy_loops`) are not children of the tests, so the course's load meter counts
them as the neighbours they stand for: another student's kernel, a browser, another CI job.

Prints each stage's result and time as it ends, then per stage the pass count, the median and the
slowest time, and every failed test with the first line of its message, its worker and the files that
worker ran before it. Exits 1 unless every stage of every run passed.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET

from benchmarks.junit_workers import WORKER_PROPERTY
from tools.busy_loops import busy_loops

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STAGES = ("logic", "timing", "notebooks")
EARLIER_FILES = 4  # a failure names at most this many files its worker ran before the failed one


@dataclasses.dataclass
class StageRun:
    stage: str
    run: int
    passed: bool
    seconds: float
    counts: str  # pytest's last line: "826 passed, 2 skipped in 301.2s"
    failures: list[tuple[str, str]]  # (test id, first line of its message)


def failures_in(junit_path: str) -> list[tuple[str, str]]:
    """The failed and erroring tests of a JUnit XML report, with the first line of each message.

    Where the report names each test's worker (:mod:`benchmarks.junit_workers`), the message ends with
    that worker and the last files it ran before the failed test's file: a test can fail for what an
    earlier file left in the same process."""
    if not os.path.exists(junit_path):
        return []
    found, ran = [], {}  # ran: worker -> its files (JUnit class names), in the order they started
    for case in ET.parse(junit_path).getroot().iter("testcase"):
        worker = next((p.get("value") for p in case.iter("property") if p.get("name") == WORKER_PROPERTY),
                      None)
        module = case.get("classname", "")
        files = ran.setdefault(worker, [])
        if module not in files:
            files.append(module)
        for problem in list(case.findall("failure")) + list(case.findall("error")):
            test_id = f"{module}::{case.get('name', '')}"
            message = (problem.get("message") or problem.text or "").strip().splitlines()
            text = message[0][:300] if message else "(no message)"
            if worker is not None:
                before = files[:files.index(module)][-EARLIER_FILES:]
                text += f" [on {worker}, after {', '.join(before) or 'no other file'}]"
            found.append((test_id, text))
    return found


def run_stage(stage: str, run: int, scratch: str) -> StageRun:
    junit = os.path.join(scratch, f"{stage}-{run}.xml")
    started = time.monotonic()
    extra = f"PYTEST_EXTRA=--junitxml={junit} -p benchmarks.junit_workers"
    done = subprocess.run(["make", "-s", "--no-print-directory", stage, extra],
                          cwd=REPO, capture_output=True, text=True)
    seconds = time.monotonic() - started
    lines = [line for line in done.stdout.strip().splitlines() if line.strip()]
    failures = failures_in(junit)
    if done.returncode != 0 and not failures:  # it failed before or outside pytest's tests
        failures = [(f"make {stage}", (done.stderr.strip().splitlines() or ["exit code "
                                                                             f"{done.returncode}"])[-1])]
    return StageRun(stage, run, done.returncode == 0, seconds, lines[-1] if lines else "(no output)",
                    failures)


def summary(results: list[StageRun], stages: list[str], runs: int) -> str:
    out = []
    for stage in stages:
        mine = [r for r in results if r.stage == stage]
        times = [r.seconds for r in mine]
        out.append(f"{stage:<10} {sum(r.passed for r in mine)}/{runs} passed; "
                   f"median {statistics.median(times):.0f} s, slowest {max(times):.0f} s")
    failed = [(r, f) for r in results for f in r.failures]
    if failed:
        out.append("failures:")
        out += [f"  run {r.run} {r.stage}: {test_id}: {message}" for r, (test_id, message) in failed]
    return "\n".join(out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="make test's stages, N times, beside K busy processes.")
    parser.add_argument("--runs", type=int, default=3, help="complete runs (1-50, default 3)")
    parser.add_argument("--busy", type=int, default=0, help="CPU-bound processes beside them (0-16)")
    parser.add_argument("--stages", nargs="+", default=list(STAGES), choices=STAGES, metavar="STAGE",
                        help=f"which stages, in order (default: {' '.join(STAGES)})")
    args = parser.parse_args(argv)
    if not 1 <= args.runs <= 50:
        parser.error(f"--runs must be 1..50, got {args.runs}")
    if not 0 <= args.busy <= 16:
        parser.error(f"--busy must be 0..16, got {args.busy}")
    results: list[StageRun] = []
    with tempfile.TemporaryDirectory(prefix="course-soak-") as scratch, busy_loops(args.busy):
        print(f"soak: {args.runs} run(s) of {', '.join(args.stages)} beside {args.busy} busy "
              f"process(es) on {os.cpu_count()} CPUs", flush=True)
        for run in range(1, args.runs + 1):
            for stage in args.stages:
                result = run_stage(stage, run, scratch)
                results.append(result)
                print(f"run {run}/{args.runs} {stage}: {'PASS' if result.passed else 'FAIL'} in "
                      f"{result.seconds:.0f} s: {result.counts}", flush=True)
    print(summary(results, args.stages, args.runs))
    return 0 if all(r.passed for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
