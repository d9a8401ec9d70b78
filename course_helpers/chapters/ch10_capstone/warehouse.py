"""The simulated warehouse: its walls, shelves and docks, and what the robot's sensors see in it."""

from __future__ import annotations

import math

import numpy as np

WALLS = (-3.0, -3.0, 7.0, 5.0)  # x_min, y_min, x_max, y_max of the building [m]
SHELVES = {  # pick positions in the map frame [m]
    "A1": (1.5, 1.0),
    "A2": (3.0, 1.0),
    "B1": (1.5, -1.0),
    "B2": (2.5, -1.0),
}
HOMES = {"robot1": (0.0, 0.0), "robot2": (0.0, 2.5), "robot3": (0.0, -2.0),
         "robot4": (1.5, 0.4), "robot5": (1.5, -0.4)}  # 4 and 5: the exercise's fleet, near the shelves
SPEED_LIMIT = 2.0  # the fastest any robot may be told to go [m/s]


def home_of(namespace: str) -> tuple[float, float]:
    """The dock [m] of the robot under ``namespace`` ('/robot2' -> (0.0, 2.5)); (0, 0) if unknown."""
    robot = namespace.strip("/").split("/")[-1] if namespace.strip("/") else "robot1"
    return HOMES.get(robot, (0.0, 0.0))


def make_frame(count: int, width: int = 160, height: int = 120) -> np.ndarray:
    """A synthetic mono8 camera frame: a dim gradient and a bright 16x16 item tag that moves.

    Args: ``count`` the frame number (moves the tag), ``width`` and ``height`` in pixels.
    Returns: a ``height`` x ``width`` uint8 array.
    """
    frame = np.tile(np.linspace(10, 120, width, dtype=np.uint8), (height, 1))
    angle = count * 0.05
    x = int(width / 2 + width / 4 * math.cos(angle)) - 8
    y = int(height / 2 + height / 4 * math.sin(angle)) - 8
    frame[y:y + 16, x:x + 16] = 250
    return frame


def cast_rays(pose, angles: np.ndarray, obstacles, range_max: float) -> np.ndarray:
    """Distances [m] from ``pose`` (x, y) along each angle [rad] to the walls or the nearest obstacle.

    ``obstacles`` are (x, y, radius) circles [m]. Returns one range per angle, at most ``range_max``.
    """
    x, y = pose
    dx, dy = np.cos(angles), np.sin(angles)
    x_min, y_min, x_max, y_max = WALLS
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(dx > 0, (x_max - x) / dx, np.where(dx < 0, (x_min - x) / dx, np.inf))
        ty = np.where(dy > 0, (y_max - y) / dy, np.where(dy < 0, (y_min - y) / dy, np.inf))
    ranges = np.minimum(tx, ty)
    for ox, oy, radius in obstacles:
        along = dx * (ox - x) + dy * (oy - y)
        disc = along ** 2 - ((ox - x) ** 2 + (oy - y) ** 2 - radius ** 2)
        hit = (disc >= 0) & (along > 0)
        t = np.where(hit, along - np.sqrt(np.maximum(disc, 0.0)), np.inf)
        ranges = np.minimum(ranges, np.where(t > 0, t, np.inf))
    return np.clip(ranges, 0.0, range_max)
