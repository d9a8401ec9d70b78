"""Versions of the installed ROS 2 packages (chapter 00's environment check, chapter 01, 07)."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version


def package_version(*distributions: str) -> str:
    """The version of the first installed distribution among ``distributions``, or 'not installed'.

    ``package_version('ros-jazzy-rclpy', 'ros-rclpy')`` tries the names in order.
    """
    for name in distributions:
        try:
            return version(name)
        except PackageNotFoundError:
            continue
    return "not installed"


def rclpy_version() -> str:
    """The installed rclpy release, e.g. '7.1.6'."""
    return package_version("ros-jazzy-rclpy", "ros-rclpy")
