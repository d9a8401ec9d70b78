"""Removing a QoS demo's nodes when it ends, whether it finished or failed."""

from __future__ import annotations


def remove_nodes(rt, *nodes) -> None:
    """Remove each of ``nodes`` (node objects or full names) from ``rt``; missing ones are skipped."""
    for node in nodes:
        rt.remove(node)
