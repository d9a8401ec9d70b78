"""Build a student's ``Node`` subclass in a chosen rclpy context, without changing its code.

A textbook node calls ``super().__init__('talker')`` with no ``context=`` argument, so it
would join rclpy's default context. While :func:`build_nodes` is active in a thread,
``Node.__init__`` in that thread uses the given context instead (and calls ``on_name``
first, so the runtime can free the name). The hook is:

* restored: ``Node.__init__`` is rclpy's own again as soon as no thread is building;
* re-entrant: a factory that builds a node inside another build gets the innermost context;
* clean on failure: a constructor that raises after ``super().__init__`` ran leaves no
  half-built node behind (it is destroyed before the error reaches the caller);
* for the factory's nodes only: a node the runtime makes for itself while a build runs (its
  hidden graph node, made on the first graph query) is created inside :func:`outside_builds`,
  so a failing or interrupted factory never destroys it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field

from rclpy.node import Node

_ORIGINAL_INIT = Node.__init__
_local = threading.local()
_lock = threading.Lock()
_active = 0  # builds in progress in all threads; Node.__init__ is patched while > 0


@dataclass
class _Frame:
    context: object
    on_name: Callable[[str, str], None] | None
    created: list = field(default_factory=list)


def _hooked_init(self, node_name, *args, **kwargs):
    stack = getattr(_local, "stack", None)
    frame = stack[-1] if stack else None
    if frame is not None and kwargs.get("context") is None:
        kwargs["context"] = frame.context
        if frame.on_name is not None:
            frame.on_name(node_name, kwargs.get("namespace") or "")
    _ORIGINAL_INIT(self, node_name, *args, **kwargs)
    if frame is not None:
        frame.created.append(self)


def _enter(frame: _Frame) -> None:
    global _active
    stack = getattr(_local, "stack", None)
    if stack is None:
        stack = _local.stack = []
    stack.append(frame)
    with _lock:
        _active += 1
        Node.__init__ = _hooked_init


def _leave() -> None:
    global _active
    _local.stack.pop()
    with _lock:
        _active -= 1
        if _active == 0:
            Node.__init__ = _ORIGINAL_INIT


def build_nodes(context, factory: Callable, *args,
                on_name: Callable[[str, str], None] | None = None, **kwargs):
    """Call ``factory(*args, **kwargs)`` with every ``Node`` it builds joining ``context``.

    ``on_name(name, namespace)`` is called before each node is created (the runtime uses it
    to destroy a running node with the same full name). Returns what the factory returned.
    If the factory raises, the nodes it had already built are destroyed and the error is
    raised again.
    """
    frame = _Frame(context, on_name)
    _enter(frame)
    try:
        return factory(*args, **kwargs)
    except BaseException:
        for node in frame.created:
            try:
                node.destroy_node()
            except Exception:  # already destroyed by the student's own cleanup
                pass
        raise
    finally:
        _leave()


@contextmanager
def outside_builds():
    """Nodes created in this thread during the block belong to no build: they get no context from
    it, and a build that fails does not destroy them (the runtime's own nodes)."""
    stack = getattr(_local, "stack", None)
    _local.stack = []
    try:
        yield
    finally:
        _local.stack = stack


def hook_installed() -> bool:
    """True while some thread is building nodes (``Node.__init__`` is patched)."""
    return Node.__init__ is not _ORIGINAL_INIT


def destroy_fully(node: Node) -> None:
    """Destroy a node and the action servers and clients it still holds, and a managed node's
    state machine.

    rclpy's ``Node.destroy_node()`` leaves action servers and clients alive, so the node would
    linger in the graph; a node class that already destroyed its own has removed them. A
    ``LifecycleNode``'s state machine holds the rcl node too, and rclpy 7.1's ``destroy_node()``
    leaves it: the node would stay in the graph until Python's garbage collector freed the object.
    """
    from rclpy.action import ActionClient, ActionServer
    from rclpy.lifecycle import LifecycleNodeMixin

    node.destroy_node()
    for waitable in list(node.waitables):
        if isinstance(waitable, (ActionServer, ActionClient)):
            waitable.destroy()
    if isinstance(node, LifecycleNodeMixin):  # private: tests/test_rclpy_private_api.py
        node._state_machine.destroy_when_not_in_use()


def bare_node(context, name: str, namespace: str = ""):
    """An rcl node without a single endpoint (no rosout, no parameter services or events).

    rmw lists it in the graph, and it keeps the context's participant alive; it is the
    ``rclpy`` handle, not a ``Node`` (so no ``Node`` search of the process finds it). End it with
    ``destroy_when_not_in_use()``.
    """
    from rclpy.impl.implementation_singleton import rclpy_implementation

    with context.handle:
        return rclpy_implementation.Node(name, namespace, context.handle, None, False, False)
