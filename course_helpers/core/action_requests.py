"""An action client's request and the response to it, kept in order when an executor spins elsewhere.

rclpy 7.1 (Jazzy, the pinned release) sends an action client's request first and records it
afterwards: ``send_goal_async`` calls ``send_goal_request``, which returns the request's sequence
number, and only then files that number with the future it returns (``_cancel_goal_async`` and
``_get_result_async`` do the same). An executor spinning in another thread can take the
response in between. ``execute`` then finds no request with that number, logs "Ignoring
unexpected goal response" and drops it, and the future never completes. Every notebook meets
this: the runtime spins in a background thread, and a cell sends goals from the kernel's main
thread (ros2/rclpy#1123; rclpy fixed it with a lock in #1308, backported to Humble and Jazzy in
October 2025, after the pinned release).

:func:`install` gives each ``ActionClient`` one re-entrant lock. Sending a request and filing it
is one step under the lock, and ``take_data``, where the executor takes responses from rcl,
waits for it. A response taken by the executor therefore always finds its request filed. rclpy
releases that ship their own lock keep it; this one is taken first, both in sending and in
taking, so the two never wait for each other in opposite order.
"""

from __future__ import annotations

import functools
import threading

from rclpy.action import ActionClient

_LOCK_ATTRIBUTE = "_course_request_lock"
_installed: list[bool] = []

# each one sends a request and files its sequence number, or takes the responses to them
LOCKED_METHODS = ("send_goal_async", "_cancel_goal_async", "_get_result_async", "take_data")


def request_lock(client: ActionClient) -> threading.RLock:
    """The lock of ``client``, made on first use (clients made before :func:`install` get one too)."""
    lock = client.__dict__.get(_LOCK_ATTRIBUTE)
    # dict.setdefault is atomic: two threads asking at once get the same lock
    return lock if lock is not None else client.__dict__.setdefault(_LOCK_ATTRIBUTE, threading.RLock())


def _under_request_lock(method):
    @functools.wraps(method)
    def locked(self, *args, **kwargs):
        with request_lock(self):
            return method(self, *args, **kwargs)
    locked.course_unlocked = method
    return locked


def install() -> None:
    """Lock every ``ActionClient``'s sending and taking (the first call; later ones do nothing)."""
    if _installed:
        return
    for name in LOCKED_METHODS:
        method = getattr(ActionClient, name)  # a rename in rclpy fails here, loudly
        setattr(ActionClient, name, _under_request_lock(method))
    _installed.append(True)


def unlocked(name: str):
    """rclpy's own ``ActionClient.<name>``, without the lock (a test shows the race with it)."""
    method = getattr(ActionClient, name)
    return getattr(method, "course_unlocked", method)
