"""The private parts of rclpy (and rcl, and CPython) the package relies on, and the public ones it
overrides or wraps, checked against the pinned release.

rclpy promises nothing about names that start with an underscore, nor about rcl's C structs. The
package uses these, each for a reason rclpy's public API does not cover (environment.txt pins
``ros-jazzy-rclpy==7.1.6``), and reads each directly where it uses it, so a rename fails loudly:

* ``Executor.spin_once_until_future_complete(future, timeout_sec)``, overridden by ``WakeOnce`` in
  ``core/executors.py`` (the future wakes the executor once, not every turn), written with
  ``wait_for_ready_callbacks(timeout_sec, nodes, condition)`` returning ``(Task, entity, node)`` and
  its ``ShutdownException``, ``TimeoutException`` and ``ConditionReachedException``; the same wait
  in ``core/sim_clock.py`` runs what is ready without blocking;
* patching ``Node.__init__(self, node_name, *, context=..., namespace=..., ...)`` in
  ``core/node_hook.py``: a textbook ``super().__init__('x')`` joins the runtime's context;
* wrapping ``rclpy.init(*, args, context, domain_id, signal_handler_options)`` in
  ``notebook/interrupts.py``: a textbook ``rclpy.init()`` installs no signal handler;
* ``rclpy.impl.implementation_singleton.rclpy_implementation.Node(name, namespace, context, cli_args,
  use_global_arguments, enable_rosout)`` in ``core/node_hook.py``: a node without a single endpoint
  (a child's participant keeper);
* ``LifecycleNodeMixin._state_machine`` in ``core/node_hook.py``: destroyed with its lifecycle node;
* ``.handle.pointer`` of a node, a context and a guard condition, and from ``librcl.so``
  ``rcl_node_get_graph_guard_condition``, the ``rcl_wait_set_*`` functions, ``rcl_wait`` and the
  ``rcl_wait_set_t`` layout, in ``core/graph_events.py``: graph changes as events;
* ``MultiThreadedExecutor._executor`` and ``._futures``, ``Executor._tasks`` (a list of (task, entity,
  node); newer rclpy has ``_pending_tasks`` and ``_ready_tasks`` instead), in ``core/executors.py``
  and ``chapters/ch04_services.py``: let queued callbacks finish, or see them, before a teardown;
* ``Client._pending_requests`` in ``chapters/ch04_services.py``: release a callback blocked in
  ``client.call()`` at teardown; and in ``checks/ch04_services.py``: a callback that awaits an answer
  its own mutually exclusive group keeps out (a deadlock by construction);
* ``Client.call`` living in ``rclpy/client.py``, and CPython's ``sys._current_frames()``, in
  ``chapters/ch04_services.py``: a callback of a single-threaded executor waiting in ``call()``
  (a deadlock by construction);
* ``ActionClient._cancel_goal_async`` and ``._get_result_async``, wrapped with the public
  ``send_goal_async`` and ``take_data`` in ``core/action_requests.py``: a response is never taken
  before its request is filed (ros2/rclpy#1123); ``tests/test_action_requests.py`` also reads
  ``ActionClient._client_handle`` and ``._is_goal_response_ready`` to make that race happen;
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


def test_the_spin_loop_overrides_and_calls_what_rclpy_has():
    from rclpy import executors

    assert _parameters(Executor.spin_once_until_future_complete)[:3] == ["self", "future", "timeout_sec"], (
        _changed("Executor.spin_once_until_future_complete(future, timeout_sec)", "core/executors.py"))
    waits = _parameters(Executor._wait_for_ready_callbacks)  # wait_for_ready_callbacks(*args, **kwargs)
    assert waits[:4] == ["self", "timeout_sec", "nodes", "condition"], (
        _changed("Executor._wait_for_ready_callbacks(timeout_sec, nodes, condition), which "
                 "wait_for_ready_callbacks passes its arguments to",
                 "core/executors.py and core/sim_clock.py"))
    for name in ("ShutdownException", "TimeoutException", "ConditionReachedException"):
        assert issubclass(getattr(executors, name, None) or object, Exception), _changed(
            f"rclpy.executors.{name}", "core/executors.py (WakeOnce)")


def test_rclpy_init_takes_the_keywords_the_wrapper_passes():
    parameters = inspect.signature(rclpy.init).parameters
    for keyword in ("args", "context", "domain_id", "signal_handler_options"):
        kind = getattr(parameters.get(keyword), "kind", None)
        assert kind is inspect.Parameter.KEYWORD_ONLY, _changed(f"rclpy.init's keyword {keyword!r}",
                                                                "notebook/interrupts.py")


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


def test_a_client_keeps_its_pending_requests_and_waits_in_client_py(context):
    from rclpy.client import Client
    from std_srvs.srv import Trigger

    from course_helpers.chapters.ch04_services import CLIENT_MODULE

    node = Node("private_api_entities", context=context)
    try:
        client = node.create_client(Trigger, "private_api_trigger")
        assert isinstance(getattr(client, "_pending_requests", None), dict), _changed(
            "Client._pending_requests", "chapters/ch04_services.py and checks/ch04_services.py")
        assert Client.call.__code__.co_filename.endswith(CLIENT_MODULE), _changed(
            f"where Client.call is defined (now {Client.call.__code__.co_filename})",
            "chapters/ch04_services.py (waiting_in_a_call)")
        assert callable(getattr(sys, "_current_frames", None)), (
            "this Python has no sys._current_frames(): chapters/ch04_services.py reads the executor "
            "thread's stack with it")
    finally:
        node.destroy_node()


def test_the_action_client_methods_the_request_lock_wraps_exist(context):
    from course_interfaces.action import Fibonacci
    from rclpy.action import ActionClient

    from course_helpers.core.action_requests import LOCKED_METHODS, unlocked

    for name in LOCKED_METHODS:
        assert callable(unlocked(name)), _changed(f"ActionClient.{name}", "core/action_requests.py")
    node = Node("private_api_action", context=context)
    try:
        client = ActionClient(node, Fibonacci, "private_api_action")
        assert hasattr(client, "_client_handle"), _changed("ActionClient._client_handle",
                                                          "tests/test_action_requests.py")
        assert "self._is_goal_response_ready" in inspect.getsource(unlocked("take_data")), _changed(
            "ActionClient._is_goal_response_ready (set by is_ready, read by take_data)",
            "tests/test_action_requests.py")
        client.destroy()
    finally:
        node.destroy_node()


def test_a_lifecycle_node_keeps_its_state_machine(context):
    from rclpy.lifecycle import LifecycleNode

    node = LifecycleNode("private_api_lifecycle", context=context)
    try:
        assert hasattr(getattr(node, "_state_machine", None), "destroy_when_not_in_use"), _changed(
            "LifecycleNodeMixin._state_machine", "core/node_hook.py (destroy_fully)")
    finally:
        node_hook.destroy_fully(node)


def test_rcl_errors_keep_their_class():
    from rclpy._rclpy_pybind11 import RCLError

    assert issubclass(RCLError, Exception), _changed("rclpy._rclpy_pybind11.RCLError",
                                                     "chapters/ch08b_lab/publisher.py")
