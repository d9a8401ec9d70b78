"""Changes of the ROS graph as events: what rclpy 7.1.6 does not expose, taken from rcl directly.

rcl gives every node a *graph guard condition* that the middleware triggers whenever its view of
the graph changes (a participant, node, publisher, subscription, service or client came or went).
rclpy 7.1.6 keeps it to itself: its own ``Node.wait_for_node`` and ``Client.wait_for_service``
poll every 0.1 s and 0.25 s (the comment there points at ros2/rclpy#929). :class:`GraphWatcher`
waits on that guard condition in a thread of its own, through an rcl wait set made with
``ctypes`` from ``librcl.so`` (the library rclpy itself is built on, with its C headers in the
venv), and counts the changes:

* :attr:`GraphWatcher.version` grows with every change, so the runtime can keep the answer to a
  graph query until the graph changes (:meth:`course_helpers.core.runtime.CourseRuntime.graph_nodes`);
* each change notifies :data:`course_helpers.core.waiting.changes`, so a wait for something in the
  graph is woken by the change instead of polling.

The thread blocks in ``rcl_wait`` with no timeout and costs nothing while the graph is still; a
guard condition of the watcher's own wakes it to stop. Only this thread waits on the graph guard
condition (rmw allows one waiter at a time; rclpy never waits on it). The private rcl and rclpy
parts it relies on are listed in ``tests/test_rclpy_private_api.py``.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import threading

from course_helpers.core.waiting import changes

RCL_RET_OK = 0
RCL_RET_TIMEOUT = 2
WAIT_FOREVER = -1  # ns: rcl_wait blocks until a guard condition triggers
ENTITY_KINDS = ("subscriptions", "guard_conditions", "timers", "clients", "services", "events")


class WaitSet(ctypes.Structure):
    """``rcl_wait_set_t`` (rcl/wait.h, Jazzy): six arrays of entity pointers with their sizes, and impl."""

    _fields_ = [field for kind in ENTITY_KINDS
                for field in ((kind, ctypes.c_void_p), (f"size_of_{kind}", ctypes.c_size_t))]
    _fields_ += [("impl", ctypes.c_void_p)]


class Allocator(ctypes.Structure):
    """``rcutils_allocator_t`` (rcutils/allocator.h): four function pointers and a state pointer."""

    _fields_ = [(name, ctypes.c_void_p) for name in ("allocate", "deallocate", "reallocate",
                                                     "zero_allocate", "state")]


def _load_rcl():
    """``librcl.so`` and ``librcutils.so`` of the venv, with the signatures used here."""
    folder = os.path.join(sys.prefix, "lib")
    rcl = ctypes.CDLL(os.path.join(folder, "librcl.so"), mode=ctypes.RTLD_GLOBAL)
    rcutils = ctypes.CDLL(os.path.join(folder, "librcutils.so"), mode=ctypes.RTLD_GLOBAL)
    rcutils.rcutils_get_default_allocator.restype = Allocator
    rcl.rcl_get_zero_initialized_wait_set.restype = WaitSet
    rcl.rcl_node_get_graph_guard_condition.restype = ctypes.c_void_p
    rcl.rcl_node_get_graph_guard_condition.argtypes = [ctypes.c_void_p]
    rcl.rcl_wait_set_init.argtypes = [ctypes.POINTER(WaitSet)] + [ctypes.c_size_t] * 6 + [ctypes.c_void_p,
                                                                                          Allocator]
    rcl.rcl_wait_set_add_guard_condition.argtypes = [ctypes.POINTER(WaitSet), ctypes.c_void_p,
                                                     ctypes.c_void_p]
    rcl.rcl_wait_set_clear.argtypes = [ctypes.POINTER(WaitSet)]
    rcl.rcl_wait_set_fini.argtypes = [ctypes.POINTER(WaitSet)]
    rcl.rcl_wait.argtypes = [ctypes.POINTER(WaitSet), ctypes.c_int64]
    for name in ("rcl_wait_set_init", "rcl_wait_set_add_guard_condition", "rcl_wait_set_clear",
                 "rcl_wait_set_fini", "rcl_wait"):
        getattr(rcl, name).restype = ctypes.c_int
    return rcl, rcutils


class GraphWatcher:
    """Counts the changes of the graph as ``node`` sees it (all nodes of a context share one view).

    The watcher's thread holds ``node``'s handle until :meth:`stop`: destroying the node before
    then only takes effect once the thread has ended (rclpy's ``destroy_when_not_in_use``). Raises
    OSError if rcl cannot be loaded or the wait set cannot be made.
    """

    def __init__(self, node):
        from rclpy.guard_condition import GuardCondition

        self.version = 0
        self._node = node
        self._rcl, rcutils = _load_rcl()
        self._graph = self._rcl.rcl_node_get_graph_guard_condition(node.handle.pointer)
        if not self._graph:
            raise OSError("rcl_node_get_graph_guard_condition returned NULL")
        self._wake = GuardCondition(None, None, node.context)  # ours: triggered to stop the thread
        self._wait_set = self._rcl.rcl_get_zero_initialized_wait_set()
        code = self._rcl.rcl_wait_set_init(ctypes.byref(self._wait_set), 0, 2, 0, 0, 0, 0,
                                           node.context.handle.pointer,
                                           rcutils.rcutils_get_default_allocator())
        if code != RCL_RET_OK:
            raise OSError(f"rcl_wait_set_init failed ({code})")
        self._stopping = False
        # The graph guard condition is the node's (rcl frees it with the node), so the watcher holds
        # the node's handle, and the wake condition's, from here until its thread ends: a
        # destroy_node() from another thread meanwhile is deferred instead of freeing what rcl_wait
        # waits on (a procedure interrupted inside rt.build destroyed the node under it: a crash).
        self._held = contextlib.ExitStack()
        self._held.enter_context(node.handle)
        self._held.enter_context(self._wake.handle)
        self._thread = threading.Thread(target=self._watch, name="graph-watcher", daemon=True)
        self._thread.start()

    def _watch(self) -> None:
        wake = self._wake.handle.pointer
        slots = ctypes.cast(self._wait_set.guard_conditions, ctypes.POINTER(ctypes.c_void_p))
        try:
            while not self._stopping:
                self._rcl.rcl_wait_set_clear(ctypes.byref(self._wait_set))
                self._rcl.rcl_wait_set_add_guard_condition(ctypes.byref(self._wait_set), self._graph, None)
                self._rcl.rcl_wait_set_add_guard_condition(ctypes.byref(self._wait_set), wake, None)
                code = self._rcl.rcl_wait(ctypes.byref(self._wait_set), WAIT_FOREVER)
                if code not in (RCL_RET_OK, RCL_RET_TIMEOUT):
                    return  # the context is gone: nothing more will change
                if slots[0]:  # rcl leaves the pointers of triggered entities, NULLs the others
                    self.version += 1
                    changes.notify()
        finally:
            self._rcl.rcl_wait_set_fini(ctypes.byref(self._wait_set))  # before the handles go
            self._held.close()  # a destroy requested meanwhile happens now
            self.version += 1  # whoever cached an answer asks again
            changes.notify()

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def stop(self, timeout: float = 5.0) -> None:
        """End the thread and free the wait set (before the node or its context goes)."""
        self._stopping = True
        try:
            self._wake.trigger()
        except Exception:  # the context is shut down already: rcl_wait has returned with an error
            pass
        self._thread.join(timeout)
        self._wake.destroy()  # deferred until the thread lets go of it
