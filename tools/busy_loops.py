"""CPU-bound processes beside a measurement, for the tests, benchmarks and soak runs that show what
a busy machine does to a verdict.

Each loop is a CPU-bound Python loop started through a shell that exits at once, so the loop
is adopted by init (or the nearest subreaper) and is not a descendant of the caller:
:class:`course_helpers.core.machine_load.LoadMeter` counts a process tree's own children as its own
work, and a real neighbour (another student's kernel, a browser) is not one of them.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from collections.abc import Iterator

# The loop looks every few million turns (a fraction of a second) whether its owner still runs, and ends
# when it does not: adopted by init, it would otherwise outlive a test that was killed.
LOOP = ("import os, sys\n"
        "owner = int(sys.argv[1])\n"
        "while True:\n"
        "    for _ in range(2_000_000): pass\n"
        "    try: os.kill(owner, 0)\n"
        "    except ProcessLookupError: break\n")


def start_busy_loop() -> int:
    """Start one CPU-bound loop outside this process tree, ending with this process; its PID."""
    command = f"'{sys.executable}' -c \"$0\" {os.getpid()} >/dev/null 2>&1 & echo $!"
    shell = subprocess.run(["sh", "-c", command, LOOP], capture_output=True, text=True, check=True)
    return int(shell.stdout.strip())


@contextlib.contextmanager
def busy_loops(count: int) -> Iterator[list[int]]:
    """``count`` CPU-bound loops for the duration of the block (their PIDs); killed afterwards."""
    pids = [start_busy_loop() for _ in range(count)]
    try:
        yield pids
    finally:
        for pid in pids:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
