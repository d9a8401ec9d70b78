"""The ROS runtime of a kernel: one context, one background executor, re-run-safe nodes.

Every chapter starts with ``rt = get_runtime()``. The runtime

* owns its own rclpy ``Context`` with signal handlers off (the stop button never shuts ROS down);
* spins one background executor thread (single-threaded by default; chapter 02 opts into
  multi-threaded to teach callback groups);
* keeps node names unique: a node whose name is taken is destroyed first (no duplicates on re-run);
* waits for futures, conditions and messages from the notebook without spinning (:mod:`.runtime_waits`);
* runs nodes in child processes through the process layer, and stops them with itself;
* isolates each kernel in its own ROS domain with localhost-only discovery;
* heals: if its context is shut down from outside (``rclpy.shutdown(context=rt.context)``, or
  an interrupt while an rclpy signal handler is installed), the next use stops everything that
  is left and starts afresh, and says in one line which cells to run again (:mod:`.healing`).

In a notebook, a textbook ``rclpy.init()`` installs no signal handler, so an interrupt never
shuts this context down (:mod:`course_helpers.notebook.interrupts`).
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import os
import sys
import threading
import time
from collections.abc import Callable

from rclpy.context import Context
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions, get_current_signal_handlers_options, uninstall_signal_handlers

from course_helpers.core import console as _console
from course_helpers.core import processes
from course_helpers.core.dds_config import (
    LATE_PROFILE,
    apply_course_discovery,
    init_context,
    profile_comes_too_late,
)
from course_helpers.core.domains import DomainChoice, choose_domain
from course_helpers.core.errors import CourseError
from course_helpers.core.executors import (
    CourseMultiThreadedExecutor,
    CourseSingleThreadedExecutor,
    SpinThread,
)
from course_helpers.core.graph_view import GraphView
from course_helpers.core.healing import Origins
from course_helpers.core.kernel_shutdown import shut_down_and_say
from course_helpers.core.logs import RosoutReader, log_to_consoles
from course_helpers.core.names import as_full_name, full_name
from course_helpers.core.node_hook import build_nodes, destroy_fully
from course_helpers.core.runtime_waits import NotebookWaits
from course_helpers.core.spawning import ChildNodes
from course_helpers.core.status import status_of, status_table
from course_helpers.core.validation import (
    check_namespace,
    check_node_name,
)

EXECUTORS = ("single", "multi")
HANDLER_REMOVED = ("rclpy's signal handler has been removed again, so the interrupt button stops "
                   "only the cell.")
INTERNAL_ERRORS_LOG = "runtime-errors.log"  # in log_dir: the tracebacks of the runtime's own threads


def _children_method(method: Callable) -> Callable:
    """A runtime method that calls ``method`` on the runtime's ChildNodes (same name, signature, docs)."""
    @functools.wraps(method)
    def call(self, *args, **kwargs):
        return method(self._children, *args, **kwargs)

    return call


class CourseRuntime(NotebookWaits):
    """One per kernel: see the module docstring. Get it with :func:`get_runtime`."""

    def __init__(self, executor: str = "single", threads: int = 4):
        _check_executor(executor)
        self.executor_kind = executor
        self.threads = threads
        self.domain: DomainChoice | None = None
        self.context: Context | None = None
        self.executor = None
        self.errors: list[str] = []
        self.restarts = 0  # how often the runtime healed itself
        self.origins = Origins()  # which cell added each node and child, for the healing notice
        self._nodes: dict[str, Node] = {}
        self._node_consoles: dict[int, _console.NodeConsole] = {}
        self._spinner: SpinThread | None = None
        self._lock = threading.RLock()
        self._active = False  # started and not stopped by us
        self._started_at = 0.0
        self._router = _console.ConsoleRouter()
        self._in_kernel = _console.in_jupyter_kernel()
        self._graph: GraphView | None = None
        self._graph_spun = False
        self._log_reader: RosoutReader | None = None
        self._children = ChildNodes(self._graph_view, self._router if self._in_kernel else None,
                                    self._ensure_running)

    # ------------------------------------------------------------------ lifecycle
    @property
    def running(self) -> bool:
        """True while the background executor spins and the context is valid."""
        return bool(self._spinner and self._spinner.alive and self.context and self.context.ok())

    @property
    def log_dir(self) -> str:
        """The folder where this process keeps its children's output."""
        return processes.log_dir()

    def start(self) -> CourseRuntime:
        """Create the context and start the executor thread (a no-op if already running)."""
        with self._lock:
            if self.running:
                return self
            if self._active:  # shut down from outside: clear what is left first
                self._heal()
                return self
            self.domain = choose_domain()
            if profile_comes_too_late():
                print(LATE_PROFILE, flush=True)
            apply_course_discovery(processes.log_dir())  # before the first participant exists
            self.context = Context()
            args = ["--ros-args", "--disable-stdout-logs"] if self._in_kernel else None
            init_context(self.context, self.domain.domain_id, args)
            if self.executor_kind == "multi":
                self.executor = CourseMultiThreadedExecutor(self.context, self.threads, self._record_error)
            else:
                self.executor = CourseSingleThreadedExecutor(self.context, self._console_of_node,
                                                             self._router, self._record_error)
            if self._in_kernel:
                self._router.start()
                self._log_reader = RosoutReader(
                    self.context, log_to_consoles(self._router),
                    lambda exc: self._internal_error("the /rosout reader", exc))
            self._spinner = SpinThread(self.executor, "ros-executor",
                                       lambda exc: self._internal_error("the executor", exc),
                                       on_exit=lambda: self._router.enter(None)).start()
            self._active = True
            self._started_at = time.monotonic()
        return self

    def stop(self) -> None:
        """Stop children, destroy nodes, join the executor thread and shut the context down."""
        with self._lock:
            for bags in ("course_helpers.core.bags.recorder", "course_helpers.core.bags.player"):  # loaded:
                _quietly(getattr(sys.modules.get(bags), "stop_all", lambda: None))  # close while it spins
            self._active = False
            self.stop_children(list(self.children()))
            if self._spinner is not None:
                self._spinner.stop()
                self._spinner = None
            for fqn in list(self._nodes):
                self._destroy(self._nodes.pop(fqn))
            self._node_consoles.clear()
            if self._log_reader is not None:
                self._log_reader.stop()
                self._log_reader = None
            if self._graph is not None:
                self._graph.close()
                self._graph = None
                self._graph_spun = False
            if self.executor is not None:
                _quietly(self.executor.shutdown, timeout_sec=1.0)
                self.executor = None
            if self.context is not None and self.context.ok():
                self.context.try_shutdown()
            self._router.stop()
            self.origins.clear()

    def restart(self, executor: str | None = None) -> CourseRuntime:
        """Stop and start again (optionally switching to the 'single' or 'multi' executor)."""
        if executor is not None:
            _check_executor(executor)
        self.stop()
        if executor is not None:
            self.executor_kind = executor
        return self.start()

    def _heal(self) -> None:
        """The context was shut down from outside: stop everything left, start again, and say in
        one line which cells to run again."""
        handler = ""
        if get_current_signal_handlers_options() != SignalHandlerOptions.NO:
            uninstall_signal_handlers()
            handler = HANDLER_REMOVED
        notice = self.origins.healed_notice(list(self._nodes), list(self.children()), handler)
        self.stop()
        self.restarts += 1
        self.start()
        print(notice, flush=True)

    def _ensure_running(self) -> None:
        if not self.running:
            self.start()

    # ------------------------------------------------------------------ nodes
    def build(self, factory: Callable, *args, **kwargs):
        """Call ``factory(*args, **kwargs)`` so that every node it builds joins this runtime's context.

        Names are checked and a running node with the same full name is destroyed first. The
        nodes are not spun (see :meth:`add`); a constructor that fails leaves nothing behind.
        """
        self._ensure_running()
        built = build_nodes(self.context, factory, *args, on_name=self._free_name, **kwargs)
        self._graph_changed()
        return built

    def add(self, node_or_factory, *args, console: bool | None = None, **kwargs) -> Node:
        """Spin a node in the background and return it.

        Pass a Node subclass (or any callable returning a node) and its arguments:
        ``rt.add(Talker)``. The node is created in the runtime's context. If a node with the
        same full name is running, it is destroyed first, so re-running a cell replaces the
        node instead of duplicating it. In a notebook, the node's prints and logs appear in a
        console under the cell (``console=False`` hides it).
        """
        self._ensure_running()
        if isinstance(node_or_factory, Node):
            if args or kwargs:
                raise CourseError("pass arguments only with a class: rt.add(Talker, rate_hz=5)")
            node = node_or_factory
            if node.context is not self.context:
                raise CourseError(
                    f"node {node.get_name()!r} belongs to another rclpy context. Let the runtime "
                    "create it: rt.add(MyNode) instead of rt.add(MyNode()), or build it with "
                    "context=rt.context.")
            self._evict(node.get_fully_qualified_name(), keep=node)
        elif callable(node_or_factory):
            node = self.build(node_or_factory, *args, **kwargs)
            if not isinstance(node, Node):
                raise CourseError(f"{getattr(node_or_factory, '__name__', node_or_factory)!r} returned "
                                  f"{type(node).__name__}, not an rclpy Node")
        else:
            raise CourseError(f"rt.add() takes a Node subclass, a function returning a node, or a "
                              f"node; got {type(node_or_factory).__name__}")
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
               else as_full_name(node_or_name))
        with self._lock:
            node = self._nodes.pop(fqn, None)
        if node is None:
            return False
        self.origins.forget_node(fqn)
        self._destroy(node)
        return True

    def remove_all(self) -> None:
        """Destroy every node the notebook added (the runtime keeps running)."""
        for fqn in list(self._nodes):
            self.remove(fqn)

    def nodes(self) -> list[str]:
        """Full names of the nodes this kernel spins, sorted."""
        self._ensure_running()
        return sorted(self._nodes)

    def get(self, fqn: str) -> Node:
        """The running node with this full name, e.g. ``rt.get('/talker')``."""
        try:
            return self._nodes[as_full_name(fqn)]
        except KeyError:
            raise CourseError(f"no node {fqn!r} in this kernel; running: "
                              f"{', '.join(self.nodes()) or 'none'}") from None

    def _free_name(self, name: str, namespace: str) -> None:
        check_node_name(name)
        self._evict(full_name(check_namespace(namespace), name))

    def _register(self, node: Node, console: bool | None) -> None:
        fqn = node.get_fully_qualified_name()
        with self._lock:
            self._nodes[fqn] = node
            self.origins.node_added(fqn)
            if self._in_kernel:
                show = console is None or bool(console)
                self._node_consoles[id(node)] = self._router.open(node.get_logger().name, fqn, show=show)
        self.executor.add_node(node)

    def _evict(self, fqn: str, keep: Node | None = None) -> None:
        with self._lock:
            old = self._nodes.get(fqn)
            if old is None or old is keep:
                return
            del self._nodes[fqn]
        self._destroy(old)

    def _graph_changed(self) -> None:
        if self._graph is not None:
            self._graph.changed()

    def _destroy(self, node: Node) -> None:
        """Remove a node from the executor and destroy it in the executor's own thread."""
        def destroy():
            if self.executor is not None:
                self.executor.remove_node(node)
            destroy_fully(node)

        self._node_consoles.pop(id(node), None)
        self._router.close(node.get_logger().name)
        if self.running and not self._in_executor_thread():
            self.call_in_executor(destroy, timeout=5.0)
        else:
            _quietly(destroy)
        self._graph_changed()

    def _console_of_node(self, node):
        return self._node_consoles.get(id(node)) if node is not None else None

    def _in_executor_thread(self) -> bool:
        return self._spinner is not None and threading.current_thread() is self._spinner.thread

    # ------------------------------------------------------------------ child processes (core/spawning.py)
    @functools.wraps(ChildNodes.spawn)
    def spawn(self, name: str, *args, **kwargs) -> processes.ChildProcess:
        self.origins.child_started(name)  # first: a child whose wait fails still runs
        return self._children.spawn(name, *args, **kwargs)

    @functools.wraps(ChildNodes.stop_children)
    def stop_children(self, names) -> dict[str, int | None]:
        names = list(names)
        for name in names:
            self.origins.forget_child(name)
        return self._children.stop_children(names)

    def stop_child(self, name: str) -> int | None:
        """Stop a child process by name (SIGTERM, then SIGKILL); returns its exit code."""
        return self.stop_children([name]).get(name)

    wait_for_child_node = _children_method(ChildNodes.wait_for_child_node)
    children = _children_method(ChildNodes.children)

    # ------------------------------------------------------------------ the graph
    def graph_nodes(self, include_hidden: bool = False) -> list[str]:
        return self._graph_view().nodes(include_hidden)

    @property
    def graph(self) -> Node:
        """The runtime's hidden node, for graph queries (``rt.graph.get_topic_names_and_types()``).

        It is spun by the executor from then on, so subscriptions and clients created on it work.
        """
        node = self._graph_view().node
        if not self._graph_spun:
            self.executor.add_node(node)  # every spun node costs time in each wait: only when needed
            self._graph_spun = True
        return node

    def settle_graph(self) -> None:
        self._graph_view().settle()

    graph_nodes.__doc__ = GraphView.nodes.__doc__
    settle_graph.__doc__ = GraphView.settle.__doc__

    def graph_if_running(self) -> Node | None:
        """The hidden graph node while the runtime runs, else None (never starts the runtime)."""
        with self._lock:
            if not self.running:
                return None
        return self._graph_view().node

    def _graph_view(self) -> GraphView:
        """The graph as this runtime sees it (its hidden node, made on first use)."""
        self._ensure_running()
        with self._lock:
            if self._graph is None:
                self._graph = GraphView(self.context, self._started_at)
            return self._graph

    # ------------------------------------------------------------------ status
    def status(self) -> dict:
        """Versions, middleware, domain, discovery range, nodes, child processes, and the other
        notebooks of this Jupyter server that run ROS (:func:`.status.status_of`)."""
        self._ensure_running()
        return status_of(self)

    def show_status(self) -> None:
        print(status_table(self.status()))  # status() as an aligned table

    shutdown_other_kernels = staticmethod(shut_down_and_say)  # this user's other kernels (.kernel_shutdown)

    def _record_error(self, console, where: str, exc: BaseException) -> None:
        """A node's callback raised: its traceback goes to the node's console (or the cell's output)."""
        self.errors.append(f"{where}: {type(exc).__name__}: {exc}")
        self._router.write_error(console, where, exc)

    def _internal_error(self, where: str, exc: BaseException) -> None:
        """The runtime's own thread ('the executor', 'the /rosout reader') failed: one line for the
        student, the traceback in :data:`INTERNAL_ERRORS_LOG` in :attr:`log_dir`."""
        self.errors.append(f"{where}: {type(exc).__name__}: {exc}")
        self._router.write_internal_error(where, exc, os.path.join(self.log_dir, INTERNAL_ERRORS_LOG))


def _check_executor(kind) -> None:
    if kind not in EXECUTORS:
        raise CourseError(f"executor must be 'single' or 'multi', got {kind!r}")


def _quietly(function: Callable, *args, **kwargs) -> None:
    """Run a clean-up step whose failure means there is nothing left to clean (a dead context)."""
    with contextlib.suppress(Exception):
        function(*args, **kwargs)


# ---------------------------------------------------------------------- module API
_runtime: CourseRuntime | None = None


def get_runtime(executor: str | None = None) -> CourseRuntime:
    """Return this process's runtime, starting it on first use (or after it was stopped).

    ``executor='multi'`` switches to a MultiThreadedExecutor (chapter 02); the runtime
    restarts, and the nodes the notebook had added must be added again.
    """
    global _runtime
    if executor is not None:
        _check_executor(executor)
    if _runtime is None:
        _runtime = CourseRuntime(executor or "single")
        atexit.register(shutdown_runtime)
    elif executor is not None and executor != _runtime.executor_kind:
        _runtime.restart(executor)
    _runtime.start()
    return _runtime


def shutdown_runtime() -> None:
    """Stop this process's runtime if it runs (the next :func:`get_runtime` starts a new one)."""
    if _runtime is not None:
        _runtime.stop()

