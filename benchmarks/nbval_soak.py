"""Soak: the whole strict nbval of the course, N times, with a CPU-bound process beside it.

Run with ``.venv/bin/python benchmarks/nbval_soak.py --runs 5`` from the repository root. Each run
is ``make notebooks`` (strict nbval of every notebook, then every notebook once more in the same
kernel, with the same workers and timeouts as ``make test``). A busy process keeps one core at
100 % for the whole soak, as another job on a CI runner would. Prints each run's result and time,
and the pass count at the end; exits 1 unless every run passed.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import subprocess
import sys
import tempfile
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def burn(stop) -> None:
    """Keep one core busy with pure-Python arithmetic until ``stop`` is set."""
    total = 0
    while not stop.is_set():
        for i in range(100_000):
            total += i * i


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Strict nbval of the course, N times, beside a busy core.")
    parser.add_argument("--runs", type=int, default=5, help="how many complete runs (default 5)")
    parser.add_argument("--jobs", type=int, default=None,
                        help="pytest workers (default: the Makefile's NB_JOBS, as make test uses)")
    parser.add_argument("--no-busy", action="store_true", help="without the CPU-bound process")
    args = parser.parse_args(argv)
    if not 1 <= args.runs <= 100:
        parser.error(f"--runs must be 1..100, got {args.runs}")
    if args.jobs is not None and not 1 <= args.jobs <= 16:
        parser.error(f"--jobs must be 1..16, got {args.jobs}")
    stop = multiprocessing.Event()
    busy = None if args.no_busy else multiprocessing.Process(target=burn, args=(stop,), daemon=True)
    if busy is not None:
        busy.start()
    passed = 0
    try:
        for run in range(1, args.runs + 1):
            jobs = [] if args.jobs is None else [f"NB_JOBS={args.jobs}"]
            print(f"run {run}/{args.runs}: make notebooks {' '.join(jobs)} "
                  f"({'with' if busy else 'without'} a busy core) ...", flush=True)
            started = time.monotonic()
            done = subprocess.run(["make", "-s", "notebooks", *jobs], cwd=REPO,
                                  capture_output=True, text=True)
            seconds = time.monotonic() - started
            summary = (done.stdout.strip().splitlines() or ["(no output)"])[-1]
            ok = done.returncode == 0
            passed += ok
            verdict = 'PASS' if ok else 'FAIL'
            print(f"run {run}/{args.runs}: {verdict} in {seconds:.0f} s: {summary}", flush=True)
            if not ok:
                failures = [line for line in done.stdout.splitlines() if line.startswith("FAILED")]
                print("\n".join(failures[:20]) or done.stdout[-3000:] + done.stderr[-2000:], flush=True)
                handle, log = tempfile.mkstemp(prefix=f"nbval-soak-run{run}-", suffix=".log")
                with os.fdopen(handle, "w") as f:
                    f.write(done.stdout + done.stderr)
                print(f"the whole output of run {run}: {log}", flush=True)
    finally:
        stop.set()
        if busy is not None:
            busy.join(timeout=5)
    print(f"\nsoak: {passed}/{args.runs} runs passed{' with a busy core beside them' if busy else ''}")
    return 0 if passed == args.runs else 1


if __name__ == "__main__":
    sys.exit(main())
