"""The two item-tag detectors of the troubleshooting section, and a stopwatch for them.

Both take a mono8 frame as ``bytes`` with its ``width`` and ``height`` and return
``(x, y, pixels)``: the tag's centre in pixels and how many pixels passed the threshold
(``(0.0, 0.0, 0)`` when there is no tag). They give the same answer; one takes far longer.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from course_helpers.chapters.ch10_capstone.warehouse import make_frame


def detect_marker_python(data: bytes, width: int, height: int, smoothing: int = 5,
                         threshold: int = 200) -> tuple[float, float, int]:
    """Find the bright item tag: box-filter each pixel over (2*smoothing+1)^2 pixels, threshold,
    average the positions. Pure Python, one pixel at a time (the prototype)."""
    size = 2 * smoothing + 1
    limit = threshold * size * size
    sum_x = sum_y = count = 0
    for y in range(smoothing, height - smoothing):
        for x in range(smoothing, width - smoothing):
            total = 0
            for dy in range(-smoothing, smoothing + 1):
                row = (y + dy) * width + x
                for dx in range(-smoothing, smoothing + 1):
                    total += data[row + dx]
            if total >= limit:
                sum_x += x
                sum_y += y
                count += 1
    return (sum_x / count, sum_y / count, count) if count else (0.0, 0.0, 0)


def detect_marker_numpy(data: bytes, width: int, height: int, smoothing: int = 5,
                        threshold: int = 200) -> tuple[float, float, int]:
    """The same detector on whole arrays: a box filter from an integral image (same result)."""
    image = np.frombuffer(data, dtype=np.uint8).reshape(height, width)
    integral = np.pad(image.astype(np.int64).cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    size = 2 * smoothing + 1
    box = (integral[size:, size:] - integral[:-size, size:]
           - integral[size:, :-size] + integral[:-size, :-size])
    ys, xs = np.nonzero(box >= threshold * size * size)
    if len(xs) == 0:
        return (0.0, 0.0, 0)
    return (float(xs.mean()) + smoothing, float(ys.mean()) + smoothing, int(len(xs)))


DETECTORS = {"python": detect_marker_python, "numpy": detect_marker_numpy}


def time_detector(detector: Callable, repeats: int = 3) -> float:
    """Run ``detector`` on one synthetic camera frame ``repeats`` times; the fastest run [ms].

    The fastest run is what the code itself costs: a slower one was interrupted by other work
    (another thread of the kernel, another process on a busy machine).
    """
    frame = make_frame(0)
    height, width = frame.shape
    data = frame.tobytes()
    runs = []
    for _ in range(repeats):
        started = time.perf_counter()
        detector(data, width, height)
        runs.append(time.perf_counter() - started)
    return min(runs) * 1000.0
