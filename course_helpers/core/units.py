"""Sizes and rates as people read them, one format for the whole course."""

from __future__ import annotations


def format_bytes(n: float, binary: bool = True) -> str:
    """A byte count for humans: binary units by default ('64 KiB', '1 MiB'), decimal with
    ``binary=False`` ('100 kB', '2 MB'). Bandwidth and message sizes that ROS tools print use
    decimal; memory and payloads chosen as powers of two use binary."""
    units = (("MiB", 2**20), ("KiB", 2**10)) if binary else (("MB", 10**6), ("kB", 10**3))
    for unit, size in units:
        if n >= size:
            return f"{n / size:g} {unit}"
    return f"{n:g} B"


def format_rate(hz: float) -> str:
    """'400 Hz', '2.5 Hz'."""
    return f"{hz:g} Hz"
