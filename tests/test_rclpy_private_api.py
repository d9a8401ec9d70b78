"""The private parts of rclpy (and rcl) that the package relies on, checked against the pinned release.

rclpy promises nothing about names that start with an underscore, nor about rcl's C structs. The
package uses these, each for a reason rclpy's public API does not cover (environment.txt pins
``ros-jazzy-rclpy==7.1.6``):

* ``Executor._spin_once_impl(timeout_sec, wait_condition)``, overridden and called in
  ``core/executors.py``: the one spin loop with a stop condition, and a console per callback;
* ``Executor.wait_for_ready_callbacks(timeout_sec, nodes, condition)`` returning ``(Task, entity,
  node)``, in ``core/executors.py``: which node a callback belongs to;
* patching ``Node.__init__(self, node_name, *, context=..., namespace=..., ...)`` in
  ``core/node_hook.py``: a textbook ``super().__init__('x')`` joins the runtime's context;
* ``rclpy.impl.implementation_singleton.rclpy_implementation.Node(name, namespace, context, cli_args,
  use_global_arguments, enable_rosout)`` in ``core/node_hook.py``: a node without a single endpoint
  (a child's participant keeper);
* ``.handle.pointer`` of a node, a context and a guard condition, and from ``librcl.so``
  ``rcl_node_get_graph_guard_condition``, the ``rcl_wait_set_*`` functions, ``rcl_wait`` and the
  ``rcl_wait_set_t`` layout, in ``core/graph_events.py``: graph changes as events;
* ``MultiThreadedExecutor._executor`` and ``._futures``, ``Executor._tasks``, in
  ``core/executors.py`` and ``chapters/ch04_services.py``: let queued callbacks finish, or see
  them, before a teardown;
* ``Client._pending_requests`` in ``chapters/ch04_services.py``: release a callback blocked in
  ``client.call()`` at teardown;
* ``ActionServer._action_type`` in ``checks/ch05_actions.py``: which action a student's server serves;
* ``rclpy._rclpy_pybind11.RCLError`` in ``chapters/ch08b_lab/publisher.py``: a full KEEP_ALL
  history (back-pressure).

Each test below fails with a message naming what changed and where the package uses it.
"""

from __future__ import annotations

import ctypes
import inspect
import os
import re
import sys

import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import Executor, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node

from course_helpers.core import graph_events, node_hook
from course_helpers.core.versions import rclpy_version

PINNED = "7.1.6"


def _changed(what: str, where: str) -> str:
    return (f"rclpy {rclpy_version()} (pinned {PINNED}) changed {what}, which {where} relies on: "
            "adapt that module, then this test")


@pytest.fixture
def context():
    ctx = Context()
    rclpy.init(context=ctx, domain_id=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0))
    yield ctx
    ctx.try_shutdown()


def _parameters(function) -> list[str]:
    return list(inspect.signature(function).parameters)


def test_the_spin_loop_hooks_are_there():
    for cls in (SingleThreadedExecutor, MultiThreadedExecutor):
        assert _parameters(cls._spin_once_impl)[:3] == ["self", "timeout_sec", "wait_condition"], (
            _changed(f"{cls.__name__}._spin_once_impl(timeout_sec, wait_condition)", "core/executors.py"))
    waits = _parameters(Executor._wait_for_ready_callbacks)
    assert waits[:4] == ["self", "timeout_sec", "nodes", "condition"], (
        _changed("Executor._wait_for_ready_callbacks(timeout_sec, nodes, condition), which "
                 "wait_for_ready_callbacks passes its arguments to", "core/executors.py"))


def test_wait_for_ready_callbacks_hands_out_a_task_its_entity_and_its_node(context):
    node = Node("private_api_probe", context=context)
    executor = SingleThreadedExecutor(context=context)
    try:
        node.create_timer(0.01, lambda: None)
        executor.add_node(node)
        handler, _entity, owner = executor.wait_for_ready_callbacks(5.0, None, lambda: False)
        handler()
        assert owner is node and handler.done() and handler.exception() is None, _changed(
            "what wait_for_ready_callbacks returns (Task, entity, node)", "core/executors.py")
    finally:
        executor.shutdown()
        node.destroy_node()


def test_node_init_takes_the_keywords_the_hook_sets():
    parameters = inspect.signature(Node.__init__).parameters
    assert list(parameters)[:2] == ["self", "node_name"], _changed("Node.__init__(self, node_name, ...)",
                                                                   "core/node_hook.py")
    for keyword in ("context", "namespace"):
        assert parameters[keyword].kind is inspect.Parameter.KEYWORD_ONLY, _changed(
            f"Node.__init__'s keyword {keyword!r}", "core/node_hook.py")


def test_a_bare_rcl_node_is_made_from_the_implementation_singleton(context):
    bare = node_hook.bare_node(context, "private_api_bare")
    try:
        assert bare.get_fully_qualified_name() == "/private_api_bare", _changed(
            "rclpy_implementation.Node(name, namespace, context, cli_args, use_global_arguments, "
            "enable_rosout)", "core/node_hook.py (bare_node)")
    finally:
        bare.destroy_when_not_in_use()


def test_the_rcl_handles_have_pointers(context):
    from rclpy.guard_condition import GuardCondition

    node = Node("private_api_pointers", context=context)
    guard = GuardCondition(None, None, context)
    try:
        handles = (("Node", node.handle), ("Context", context.handle), ("GuardCondition", guard.handle))
        for what, handle in handles:
            assert isinstance(getattr(handle, "pointer", None), int) and handle.pointer, _changed(
                f"{what}.handle.pointer (the rcl object's address)", "core/graph_events.py")
    finally:
        guard.destroy()
        node.destroy_node()


def test_rcl_has_the_wait_set_functions_and_layout_the_graph_watcher_uses():
    rcl, rcutils = graph_events._load_rcl()
    for name in ("rcl_node_get_graph_guard_condition", "rcl_get_zero_initialized_wait_set",
                 "rcl_wait_set_init", "rcl_wait_set_add_guard_condition", "rcl_wait_set_clear",
                 "rcl_wait_set_fini", "rcl_wait"):
        assert hasattr(rcl, name), f"librcl.so has no {name} any more: core/graph_events.py calls it"
    assert hasattr(rcutils, "rcutils_get_default_allocator")
    header = open(os.path.join(sys.prefix, "include", "rcl", "rcl", "wait.h"), encoding="utf-8").read()
    struct = re.search(r"typedef struct rcl_wait_set_s\s*\{(.*?)\}\s*rcl_wait_set_t;", header, re.S).group(1)
    fields = re.findall(r"^\s*[^/\n][^;]*?\b(\w+);", struct, re.M)
    ours = [name for name, _type in graph_events.WaitSet._fields_]
    assert ours == fields, (f"rcl_wait_set_t in rcl/wait.h now has the fields {fields}; "
                            f"core/graph_events.py's WaitSet mirrors {ours}")
    assert ctypes.sizeof(graph_events.WaitSet) == len(fields) * ctypes.sizeof(ctypes.c_void_p)
    init = re.search(r"\brcl_wait_set_init\(\s*rcl_wait_set_t \* wait_set,(.*?)\);", header, re.S).group(1)
    assert len(init.split(",")) == 8, f"rcl_wait_set_init now takes (wait_set,{init}); graph_events passes 9"


def test_the_executors_keep_their_pools_and_task_lists(context):
    executor = MultiThreadedExecutor(num_threads=2, context=context)
    try:
        assert hasattr(executor, "_executor") and hasattr(executor._executor, "shutdown"), _changed(
            "MultiThreadedExecutor._executor (its thread pool)",
            "core/executors.py and chapters/ch04_services.py")
        assert isinstance(getattr(executor, "_futures", None), list), _changed(
            "MultiThreadedExecutor._futures", "core/executors.py and chapters/ch04_services.py")
        assert isinstance(getattr(executor, "_tasks", None), list), _changed(
            "Executor._tasks", "chapters/ch04_services.py")
    finally:
        executor.shutdown()


def test_a_client_keeps_its_pending_requests_and_a_server_its_action_type(context):
    from course_interfaces.action import Navigate
    from rclpy.action import ActionServer
    from std_srvs.srv import Trigger

    node = Node("private_api_entities", context=context)
    try:
        client = node.create_client(Trigger, "private_api_trigger")
        assert isinstance(getattr(client, "_pending_requests", None), dict), _changed(
            "Client._pending_requests", "chapters/ch04_services.py")
        server = ActionServer(node, Navigate, "private_api_navigate", lambda handle: None)
        assert getattr(server, "_action_type", None) is Navigate, _changed(
            "ActionServer._action_type", "checks/ch05_actions.py")
        server.destroy()
    finally:
        node.destroy_node()


def test_rcl_errors_keep_their_class():
    from rclpy._rclpy_pybind11 import RCLError

    assert issubclass(RCLError, Exception), _changed("rclpy._rclpy_pybind11.RCLError",
                                                     "chapters/ch08b_lab/publisher.py")
