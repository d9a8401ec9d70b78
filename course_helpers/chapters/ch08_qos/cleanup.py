"""Small pieces the QoS demos share: a stopwatch and removing the demo's nodes."""

from __future__ import annotations

import time


class DemoClock:
    """Seconds since the demo started (``start`` may be reset once the nodes are matched)."""

    def __init__(self):
        self.start = time.monotonic()

    def now(self) -> float:
        """Seconds since :attr:`start`."""
        return time.monotonic() - self.start


def remove_nodes(rt, *nodes) -> None:
    """Remove each of ``nodes`` (node objects or full names) from ``rt``; missing ones are skipped."""
    for node in nodes:
        rt.remove(node)
