"""The ROS runtime of a kernel: one context, one background executor, re-run-safe nodes.

Every chapter starts with ``rt = get_runtime()``. The runtime

* owns its own rclpy ``Context`` with signal handlers off, so the kernel's stop
  button (SIGINT) interrupts the cell and never shuts ROS down;
* spins one background executor thread (single-threaded by default, the fastest
  here; chapter 02 opts into multi-threaded to teach callback groups);
* keeps node names unique: adding a node whose name is taken destroys the old
  one first, so re-running a cell never leaves duplicates;
* waits for futures, conditions and messages from the notebook without spinning;
* runs nodes in child processes and reaps them (chapters 01, 06-08, 10);
* isolates each kernel in its own ROS domain with localhost-only discovery;
* shuts down cleanly when stopped or when the kernel exits.
"""

from __future__ import annotations

import atexit
import os
import sys
import tempfile
import threading
import time
from collections.abc import Callable

import rclpy
from rclpy.context import Context
from rclpy.executors import (
    ConditionReachedException,
    MultiThreadedExecutor,
    ShutdownException,
    SingleThreadedExecutor,
    TimeoutException,
)
from rclpy.node import Node
from rclpy.qos import QoSDurabilityPolicy, QoSProfile, QoSReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from . import console as _console
from .domains import DomainChoice, choose_domain
from .errors import CourseError, WaitTimeout
from .processes import ChildNode, start_child
from .validation import (
    check_depth,
    check_namespace,
    check_node_name,
    check_topic_name,
    interface_name,
    resolve_interface,
)

INTERNAL_NODE = "_course_runtime"  # hidden (leading underscore), like ros2cli's daemon nodes
LOG_NODE = "_course_logs"  # hidden; in a kernel it reads /rosout for the consoles
_POLL_S = 0.005


class _RoutedCallbacks:
    """Executor mix-in: route each callback's output to its node's console; keep going on errors.

    A plain rclpy executor re-raises a callback's exception out of ``spin()``, which
    would kill the background thread; here the traceback goes to the node's console
    and the other nodes keep running.
    """

    def _spin_once_impl(self, timeout_sec=None, wait_condition=lambda: False):
        try:
            handler, _entity, node = self.wait_for_ready_callbacks(
                timeout_sec, None, wait_condition)
        except (ShutdownException, TimeoutException, ConditionReachedException):
            return
        self._run_routed(handler, node)

    def _run_routed(self, handler, node):
        runtime = self._course_runtime
        target = runtime._console_of_node(node)
        if target is not self._current_console:
            runtime._router.enter(target)
            self._current_console = target
        handler()
        exc = handler.exception()
        if exc is not None:
            where = node.get_fully_qualified_name() if node is not None else "a task"
            runtime._record_error(target, where, exc)


class _CourseSingleThreadedExecutor(_RoutedCallbacks, SingleThreadedExecutor):
    def __init__(self, runtime, context):
        super().__init__(context=context)
        self._course_runtime = runtime
        self._current_console = None


class _CourseMultiThreadedExecutor(MultiThreadedExecutor):
    """Multi-threaded executor for chapter 02; callbacks' errors are reported, not raised."""

    def __init__(self, runtime, context, num_threads):
        super().__init__(num_threads=num_threads, context=context)
        self._course_runtime = runtime

    def _spin_once_impl(self, timeout_sec=None, wait_condition=lambda: False):
        try:
            super()._spin_once_impl(timeout_sec, wait_condition)
        except Exception as exc:  # raised from a finished callback's future
            self._course_runtime._record_error(None, "a multi-threaded callback", exc)


def _spin_until_stopped(executor, stop_requested: Callable[[], bool], on_error: Callable) -> None:
    """Spin ``executor`` in this thread until ``stop_requested()`` or its context shuts down.

    No timeout (a timeout costs a new rcl timer per wait): whoever sets the stop flag
    also wakes the executor, which ends the wait. An exception never ends the thread.
    """
    context = executor.context
    while not stop_requested() and context.ok():
        try:
            executor._spin_once_impl(None, stop_requested)
        except Exception as exc:
            on_error(exc)


class _RosoutReader:
    """In a kernel: read /rosout on a hidden node, in a thread and executor of its own.

    Node logs reach the cells through /rosout. Spinning that subscription in the main
    executor would put one more node into every wait and cost about a tenth of the
    message throughput; here the thread sleeps in rcl's wait (the GIL released) until a
    log line arrives.
    """

    def __init__(self, context: Context, on_log: Callable, on_error: Callable):
        from rcl_interfaces.msg import Log

        self._stop = threading.Event()
        self._on_error = on_error
        self.node = Node(LOG_NODE, context=context, enable_rosout=False, start_parameter_services=False)
        qos = QoSProfile(depth=100, reliability=QoSReliabilityPolicy.RELIABLE,
                         durability=QoSDurabilityPolicy.VOLATILE)
        self.node.create_subscription(Log, "/rosout", on_log, qos)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self._spin, name="ros-logs", daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        _spin_until_stopped(self.executor, self._stop.is_set, self._on_error)

    def stop(self) -> None:
        """End the thread, then destroy the node (before the context shuts down)."""
        self._stop.set()
        self.executor.wake()
        self.thread.join(timeout=10)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()


class CourseRuntime:
    """One per kernel: see the module docstring. Get it with :func:`get_runtime`."""

    def __init__(self, executor: str = "single", threads: int = 4):
        if executor not in ("single", "multi"):
            raise CourseError(f"executor must be 'single' or 'multi', got {executor!r}")
        self.executor_kind = executor
        self.threads = threads
        self.domain: DomainChoice | None = None
        self.context: Context | None = None
        self.executor = None
        self.errors: list[str] = []
        self.log_dir = tempfile.mkdtemp(prefix="ros2-course-")
        self._nodes: dict[str, Node] = {}
        self._node_consoles: dict[int, _console.NodeConsole] = {}
        self._children: dict[str, ChildNode] = {}
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.RLock()
        self._router = _console.ConsoleRouter()
        self._in_kernel = _console.in_jupyter_kernel()
        self._internal: Node | None = None
        self._log_reader: _RosoutReader | None = None

    # ------------------------------------------------------------------ lifecycle
    @property
    def running(self) -> bool:
        """True while the background executor spins and the context is valid."""
        return bool(self._thread and self._thread.is_alive() and self.context
                    and self.context.ok())

    def start(self) -> CourseRuntime:
        """Create the context and start the executor thread (a no-op if already running)."""
        with self._lock:
            if self.running:
                return self
            self.domain = choose_domain()
            self.context = Context()
            args = ["--ros-args", "--disable-stdout-logs"] if self._in_kernel else None
            rclpy.init(args=args, context=self.context, domain_id=self.domain.domain_id,
                       signal_handler_options=SignalHandlerOptions.NO)
            if self.executor_kind == "multi":
                self.executor = _CourseMultiThreadedExecutor(self, self.context, self.threads)
            else:
                self.executor = _CourseSingleThreadedExecutor(self, self.context)
            self._stop.clear()
            if self._in_kernel:
                self._router.start()
            self._internal = Node(INTERNAL_NODE, context=self.context, enable_rosout=False,
                                  start_parameter_services=False)
            # The hidden node joins the executor only once something on it needs spinning
            # (a subscription or a client): every node in the executor costs time in each wait.
            if self._in_kernel:
                self._log_reader = _RosoutReader(
                    self.context, self._on_log,
                    lambda exc: self._record_error(None, "the /rosout reader", exc))
            self._thread = threading.Thread(target=self._spin, name="ros-executor", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        """Stop children, destroy nodes, join the executor thread and shut the context down."""
        with self._lock:
            self.stop_children(list(self._children))
            self._stop.set()
            if self.executor is not None:
                self.executor.wake()
            if self._thread is not None:
                self._thread.join(timeout=10)
                self._thread = None
            for fqn in list(self._nodes):
                self._destroy(self._nodes.pop(fqn))
            if self._log_reader is not None:
                self._log_reader.stop()
                self._log_reader = None
            if self._internal is not None:
                self._internal.destroy_node()
                self._internal = None
            if self.executor is not None:
                self.executor.shutdown(timeout_sec=1.0)
                self.executor = None
            if self.context is not None and self.context.ok():
                self.context.try_shutdown()
            self._router.stop()

    def restart(self, executor: str | None = None) -> CourseRuntime:
        """Stop and start again (optionally switching to the 'single' or 'multi' executor)."""
        self.stop()
        if executor is not None:
            if executor not in ("single", "multi"):
                raise CourseError(f"executor must be 'single' or 'multi', got {executor!r}")
            self.executor_kind = executor
        return self.start()

    def _spin(self) -> None:
        _spin_until_stopped(self.executor, self._stop.is_set,
                            lambda exc: self._record_error(None, "the executor", exc))
        self._router.enter(None)

    # ------------------------------------------------------------------ nodes
    def add(self, node_or_factory, *args, console: bool | None = None, **kwargs) -> Node:
        """Spin a node in the background and return it.

        Pass a Node subclass (or any callable returning a node) and its arguments:
        ``rt.add(Talker)``. The node is created in the runtime's context. If a node
        with the same full name is running, it is destroyed first, so re-running a
        cell replaces the node instead of duplicating it. In a notebook, the node's
        prints and logs appear in a console under the cell (``console=False`` hides it).
        """
        self._ensure_running()
        if isinstance(node_or_factory, Node):
            if args or kwargs:
                raise CourseError("pass arguments only with a class: rt.add(Talker, rate_hz=5)")
            node = node_or_factory
            if node.context is not self.context:
                raise CourseError(
                    f"node {node.get_name()!r} belongs to another rclpy context. Let the "
                    "runtime create it: rt.add(MyNode) instead of rt.add(MyNode()), or "
                    "build it with context=rt.context."
                )
            self._evict_duplicate(node.get_fully_qualified_name(), keep=node)
        elif callable(node_or_factory):
            with _creating_nodes_for(self):
                node = node_or_factory(*args, **kwargs)
            if not isinstance(node, Node):
                raise CourseError(
                    f"{getattr(node_or_factory, '__name__', node_or_factory)!r} returned "
                    f"{type(node).__name__}, not an rclpy Node"
                )
        else:
            raise CourseError(
                f"rt.add() takes a Node subclass, a function returning a node, or a node; "
                f"got {type(node_or_factory).__name__}"
            )
        self._register(node, console)
        return node

    def node(self, name: str, namespace: str = "", **node_kwargs) -> Node:
        """Create (or re-create) a plain node called ``name`` and spin it: ``rt.node('probe')``."""
        check_node_name(name)
        namespace = check_namespace(namespace)
        return self.add(Node, name, namespace=namespace, **node_kwargs)

    def remove(self, node_or_name) -> bool:
        """Destroy a node by object or full name ('/talker'); True if one was removed."""
        fqn = (node_or_name.get_fully_qualified_name() if isinstance(node_or_name, Node)
               else _as_fqn(node_or_name))
        with self._lock:
            node = self._nodes.pop(fqn, None)
        if node is None:
            return False
        self._destroy(node)
        return True

    def remove_all(self) -> None:
        """Destroy every node the notebook added (the runtime keeps running)."""
        for fqn in list(self._nodes):
            self.remove(fqn)

    def nodes(self) -> list[str]:
        """Full names of the nodes this kernel spins, sorted."""
        return sorted(self._nodes)

    def get(self, fqn: str) -> Node:
        """The running node with this full name, e.g. ``rt.get('/talker')``."""
        try:
            return self._nodes[_as_fqn(fqn)]
        except KeyError:
            raise CourseError(
                f"no node {fqn!r} in this kernel; running: {', '.join(self.nodes()) or 'none'}"
            ) from None

    def _register(self, node: Node, console: bool | None) -> None:
        fqn = node.get_fully_qualified_name()
        with self._lock:
            self._nodes[fqn] = node
            show = self._in_kernel if console is None else (console and self._in_kernel)
            if self._in_kernel:
                logger = node.get_logger().name
                self._node_consoles[id(node)] = self._router.open(logger, fqn, show=show)
        self.executor.add_node(node)

    def _evict_duplicate(self, fqn: str, keep: Node | None = None) -> None:
        with self._lock:
            old = self._nodes.get(fqn)
            if old is None or old is keep:
                return
            del self._nodes[fqn]
        self._destroy(old)

    def _destroy(self, node: Node) -> None:
        """Remove a node from the executor and destroy it in the executor's own thread."""
        def destroy():
            if self.executor is not None:
                self.executor.remove_node(node)
            node.destroy_node()
            _destroy_actions_of(node)

        self._node_consoles.pop(id(node), None)
        self._router.close(node.get_logger().name)
        if self.running and threading.current_thread() is not self._thread:
            self.call_in_executor(destroy, timeout=5.0)
        else:
            destroy()

    def _console_of_node(self, node):
        return self._node_consoles.get(id(node)) if node is not None else None

    # ------------------------------------------------------------------ waiting
    def call_in_executor(self, function: Callable, *args, timeout: float = 5.0):
        """Run ``function(*args)`` in the executor thread and return its result."""
        self._ensure_running()
        task = self.executor.create_task(function, *args)
        self.wait_for_future(task, timeout=timeout, what=getattr(function, "__name__", "task"))
        return task.result()

    def wait_for_future(self, future, timeout: float = 5.0, what: str = "the future"):
        """Wait (without spinning) until ``future`` is done; return its result.

        Raises :class:`WaitTimeout` naming ``what`` after ``timeout`` seconds.
        """
        done = threading.Event()
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(timeout):
            raise WaitTimeout(f"timed out after {timeout:g} s waiting for {what}")
        if future.exception() is not None:
            raise future.exception()
        return future.result()

    def wait_until(self, predicate: Callable[[], bool], timeout: float = 5.0,
                   what: str = "the condition"):
        """Wait until ``predicate()`` is true, checking every 5 ms; raise WaitTimeout if not."""
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                raise WaitTimeout(f"timed out after {timeout:g} s waiting for {what}")
            time.sleep(_POLL_S)
        return True

    def wait_for_messages(self, topic: str, msg_type, count: int = 1, timeout: float = 5.0,
                          qos: QoSProfile | int = 10) -> list:
        """Subscribe to ``topic``, return the first ``count`` messages, then unsubscribe."""
        check_topic_name(topic)
        msg_type = resolve_interface(msg_type, "msg")
        if isinstance(qos, int):
            qos = check_depth(qos)
        if isinstance(count, bool) or not isinstance(count, int) or count < 1:
            raise CourseError(f"count must be a whole number >= 1, got {count!r}")
        self._ensure_running()
        received: list = []
        sub = self._internal.create_subscription(msg_type, topic, received.append, qos)
        self._spin_internal_node()
        try:
            self.wait_until(lambda: len(received) >= count, timeout,
                            f"{count} message(s) on {topic} ({interface_name(msg_type)}); "
                            f"got {len(received)}")
        finally:
            self.call_in_executor(self._internal.destroy_subscription, sub)
        return received[:count]

    def wait_for_node(self, fqn: str, timeout: float = 10.0) -> None:
        """Wait until a node (in any process of this domain) shows up in the ROS graph."""
        fqn = _as_fqn(fqn)
        self._ensure_running()
        self.wait_until(lambda: fqn in self.graph_nodes(), timeout, f"node {fqn} in the graph")

    def graph_nodes(self, include_hidden: bool = False) -> list[str]:
        """Full names of all nodes discovered in this domain (the live graph)."""
        self._ensure_running()
        names = set()
        for name, namespace in self._internal.get_node_names_and_namespaces():
            if not include_hidden and name.startswith("_"):
                continue
            names.add(namespace.rstrip("/") + "/" + name)
        return sorted(names)

    @property
    def graph(self) -> Node:
        """The runtime's hidden node, for graph queries (``rt.graph.get_topic_names_and_types()``).

        It is spun by the executor from then on, so subscriptions and clients created on it work.
        """
        self._ensure_running()
        self._spin_internal_node()
        return self._internal

    def _spin_internal_node(self) -> None:
        """Add the hidden node to the executor (a no-op once added; graph queries alone do not need it)."""
        if self.executor is not None:
            self.executor.add_node(self._internal)

    # ------------------------------------------------------------------ children
    def spawn(self, name: str, target: str, params: dict | None = None,
              wait_for: str | None = None, timeout: float = 15.0,
              env: dict | None = None) -> ChildNode:
        """Run ``target`` ('module:callable', returning a node) in a child process.

        ``name`` labels the process; a child with the same label is stopped first.
        ``params`` are keyword arguments for the callable (JSON values). ``wait_for``
        names a node ('/talker') to wait for in the graph before returning. ``env``
        adds environment variables (e.g. another ROS_DOMAIN_ID).
        """
        check_node_name(name)
        if params is not None and not isinstance(params, dict):
            raise CourseError(f"params must be a dict of keyword arguments, got {params!r}")
        self._ensure_running()
        self.stop_child(name)
        child = start_child(name, target, params or {}, env, self.log_dir)
        self._children[name] = child
        if self._in_kernel:
            self._router.open(name, f"child process {name}", show=False)
        if wait_for:
            try:
                self.wait_until(lambda: wait_for in self.graph_nodes() or not child.alive,
                                timeout, f"child {name}'s node {wait_for}")
            except WaitTimeout:
                raise WaitTimeout(f"child {name} did not show node {wait_for} within "
                                  f"{timeout:g} s. Its output:\n{child.log()[-2000:]}") from None
            if not child.alive:
                raise CourseError(f"child {name} exited with code {child.returncode}. "
                                  f"Its output:\n{child.log()[-2000:]}")
        return child

    def stop_child(self, name: str) -> int | None:
        """Stop a child process by name (SIGTERM, then SIGKILL); returns its exit code."""
        return self.stop_children([name]).get(name)

    def stop_children(self, names) -> dict[str, int | None]:
        """Stop several child processes together: SIGTERM to all, then wait; exit codes by name.

        Unknown names are skipped. Stopping them together takes as long as the slowest one.
        """
        picked = {}
        for name in names:
            child = self._children.pop(name, None)
            if child is not None:
                self._router.close(name)
                picked[name] = child
        for child in picked.values():
            child.request_stop()
        return {name: child.stop() for name, child in picked.items()}

    def children(self) -> dict[str, ChildNode]:
        """The child processes started by this kernel, by name."""
        return dict(self._children)

    # ------------------------------------------------------------------ status
    def status(self) -> dict:
        """Versions, middleware, domain, discovery range, nodes and child processes."""
        self._ensure_running()
        return {
            "rclpy": _rclpy_version(),
            "rmw": rclpy.get_rmw_implementation_identifier(),
            "domain_id": self.domain.domain_id,
            "domain_chosen_by": self.domain.source,
            "discovery_range": os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET"),
            "executor": ("SingleThreadedExecutor" if self.executor_kind == "single"
                         else "MultiThreadedExecutor"),
            "nodes": self.nodes(),
            "children": {n: (c.pid, "running" if c.alive else f"exited {c.returncode}")
                         for n, c in self._children.items()},
            "callback_errors": len(self.errors),
        }

    def show_status(self) -> None:
        """Print :meth:`status` as an aligned table."""
        for key, value in self.status().items():
            if isinstance(value, list):
                value = ", ".join(value) or "(none)"
            elif isinstance(value, dict):
                value = ", ".join(f"{n} (pid {p}, {s})" for n, (p, s) in value.items()) or "(none)"
            print(f"{key:<18} {value}")

    def _record_error(self, console, where: str, exc: BaseException) -> None:
        self.errors.append(f"{where}: {type(exc).__name__}: {exc}")
        self._router.write_error(console, where, exc)

    def _ensure_running(self) -> None:
        if not self.running:
            self.start()

    # ------------------------------------------------------------------ rosout routing
    def _on_log(self, entry) -> None:
        stamp = entry.stamp.sec + entry.stamp.nanosec * 1e-9
        line = _console.format_log_line(entry.level, entry.name, entry.msg, stamp)
        self._router.write_log(entry.name, line)


def _destroy_actions_of(node: Node) -> None:
    """Destroy the action servers and clients a node still holds after ``destroy_node()``.

    rclpy's ``Node.destroy_node()`` leaves them alive, so the node would linger in the
    graph; a node class that already destroyed its own has removed them from the list.
    """
    from rclpy.action import ActionClient, ActionServer

    for waitable in list(node.waitables):
        if isinstance(waitable, (ActionServer, ActionClient)):
            waitable.destroy()


# ---------------------------------------------------------------------- node creation hook
_creating = threading.local()
_original_node_init = Node.__init__


def _course_node_init(self, node_name, *args, **kwargs):
    """Node.__init__ while rt.add() builds a node: use the runtime's context and free the name."""
    runtime = getattr(_creating, "runtime", None)
    if runtime is not None and kwargs.get("context") is None:
        kwargs["context"] = runtime.context
        check_node_name(node_name)
        namespace = check_namespace(kwargs.get("namespace") or "")
        runtime._evict_duplicate(namespace.rstrip("/") + "/" + node_name)
    _original_node_init(self, node_name, *args, **kwargs)


class _creating_nodes_for:
    """Context manager: nodes built in this thread join ``runtime`` (see :meth:`CourseRuntime.add`)."""

    def __init__(self, runtime: CourseRuntime):
        self.runtime = runtime

    def __enter__(self):
        Node.__init__ = _course_node_init
        _creating.runtime = self.runtime

    def __exit__(self, *exc):
        _creating.runtime = None
        return False


# ---------------------------------------------------------------------- module API
_runtime: CourseRuntime | None = None


def get_runtime(executor: str | None = None) -> CourseRuntime:
    """Return this kernel's runtime, starting it on first use (or after it was stopped).

    ``executor='multi'`` switches to a MultiThreadedExecutor (chapter 02); the
    runtime restarts, and the nodes the notebook had added must be added again.
    """
    global _runtime
    if _runtime is None:
        _runtime = CourseRuntime(executor or "single")
        atexit.register(_stop_at_exit)
    elif executor is not None and executor != _runtime.executor_kind:
        _runtime.restart(executor)
    _runtime.start()
    _register_magics_once()
    return _runtime


def _register_magics_once() -> None:
    """Make ``%ros2`` available in the notebook as soon as the runtime is used."""
    shell = _console.in_jupyter_kernel() and sys.modules["IPython"].get_ipython()
    if not shell or getattr(shell, "_course_ros2_magics", False):
        return
    try:
        from .magics import register_magics
    except ImportError:  # the magics module is optional for plain-Python use
        return
    register_magics(shell)
    shell._course_ros2_magics = True


def shutdown_runtime() -> None:
    """Stop this kernel's runtime if it runs (the next :func:`get_runtime` starts a new one)."""
    if _runtime is not None:
        _runtime.stop()


def _stop_at_exit() -> None:
    if _runtime is not None:
        _runtime.stop()


def _as_fqn(name: str) -> str:
    if not isinstance(name, str) or not name:
        raise CourseError(f"node name must be a string like '/talker', got {name!r}")
    return name if name.startswith("/") else "/" + name


def _rclpy_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    for dist in ("ros-jazzy-rclpy", "ros-rclpy"):
        try:
            return version(dist)
        except PackageNotFoundError:
            continue
    return "unknown"
