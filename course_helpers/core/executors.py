"""The executors the course spins, and the one loop that spins them (every chapter).

``SpinThread`` runs :func:`spin_until_stopped` in a background thread: the runtime's
executor, the ``/rosout`` reader of the node consoles, the isolated executors of
chapters 02 and 04 and the child processes all use it. The loop is rclpy's public
``spin_once_until_future_complete`` with a future that stopping completes: the wait has no
timeout (a timeout would cost a new rcl timer per wait), and stopping wakes it.

The future stays the same from turn to turn, because rclpy hands out one wait's callbacks over
several turns only while the arguments stay the same (a new future each turn would resume a
waiting coroutine for ever without waiting for new work). rclpy's own method adds a done callback
to that future every turn, so a plain executor's future is replaced every :data:`RENEW_TURNS`
turns; the course's executors (:class:`WakeOnce`) add theirs once.
A callback's exception never ends the thread: it is handed to ``on_error``. A context shut down
from outside ends the loop quietly (the runtime notices at its next use and heals).
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable

from rclpy.exceptions import InvalidHandle
from rclpy.executors import (
    ConditionReachedException,
    ExternalShutdownException,
    MultiThreadedExecutor,
    ShutdownException,
    SingleThreadedExecutor,
    TimeoutException,
)
from rclpy.task import Future

from course_helpers.core import action_requests
from course_helpers.core.waiting import changes

ErrorHandler = Callable[[BaseException], None]
RENEW_TURNS = 10_000  # a plain executor's stop future collects one done callback per turn: renewed this often
DESTROYED_RETRIES = 100  # waits in a row that may meet an entity destroyed meanwhile, before it is an error


class StopSignal:
    """A spin loop's stop request, as the future the loop spins with: :meth:`set` completes it (the
    caller then wakes the executor)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._future = Future()
        self._turns = 0

    def is_set(self) -> bool:
        return self._future.done()

    def future(self, renew: bool) -> Future:
        """The future for the loop's next turn: the same one, or with ``renew`` a fresh one every
        :data:`RENEW_TURNS` turns (done already if a stop was asked for meanwhile)."""
        with self._lock:
            self._turns += 1
            if renew and self._turns >= RENEW_TURNS and not self._future.done():
                self._future, self._turns = Future(), 0
            return self._future

    def set(self) -> None:
        with self._lock:
            if not self._future.done():
                self._future.set_result(None)


class OutlivesDestroyedEntities:
    """Executor mix-in: a subscription (or any entity) destroyed from another thread while the executor
    builds or reads its wait set costs a new wait, not an error.

    ``Node.destroy_subscription()`` may be called from any thread (the notebook's, while the executor
    spins in its own), and a measurement written the idiomatic way does exactly that. rclpy 7.1's wait,
    and 8.0's, lists the node's waitables first and uses them later: a subscription's event handler
    destroyed between the two makes ``add_to_wait_set`` raise ``InvalidHandle`` (its ``__enter__`` fails
    too, and is skipped, but the handler stays in the list). Reading a ready entity after the wait can
    raise the same way (ros2/rclpy#1142). The entity is gone, so nothing of it is lost: the generator
    that raised has ended, and the next call waits afresh. The executor is woken first, because a guard
    condition the failed wait took is handed out only after a wait returns.
    """

    def wait_for_ready_callbacks(self, *args, **kwargs):
        for _ in range(DESTROYED_RETRIES):
            try:
                return super().wait_for_ready_callbacks(*args, **kwargs)
            except InvalidHandle:
                self.wake()
        return super().wait_for_ready_callbacks(*args, **kwargs)  # still failing: not a passing race


class WakeOnce:
    """Executor mix-in: rclpy's public ``spin_once_until_future_complete``, written with rclpy's public
    ``wait_for_ready_callbacks``, that asks the future to wake the executor once, not every turn.
    :meth:`run_handler` runs what the wait handed out (a subclass routes it)."""

    def spin_once_until_future_complete(self, future, timeout_sec=None) -> None:
        if getattr(self, "_wakes_with", None) is not future:
            future.add_done_callback(lambda _done: self.wake())
            self._wakes_with = future
        try:
            handler, _entity, node = self.wait_for_ready_callbacks(timeout_sec, None, future.done)
        except (ShutdownException, TimeoutException, ConditionReachedException):
            return
        self.run_handler(handler, node)

    def run_handler(self, handler, node) -> None:
        handler()
        if handler.exception() is not None:
            raise handler.exception()


def spin_until_stopped(executor, stop: StopSignal, on_error: ErrorHandler) -> None:
    """Spin ``executor`` in this thread until ``stop`` is set or its context shuts down.

    A shutdown is not an error: neither the executor's own nor one from outside (rclpy raises
    ``ExternalShutdownException`` from its wait then), so it never reaches ``on_error``.

    After each callback it notifies :data:`~course_helpers.core.waiting.changes`, so a wait for what
    a callback does (a message counted, a reply stored) wakes at once. (A multi-threaded executor
    runs the callback in its pool after this; such a wait sees it at its next periodic look.)
    """
    context = executor.context
    renew = not isinstance(executor, WakeOnce)
    while not stop.is_set() and context.ok():
        try:
            executor.spin_once_until_future_complete(stop.future(renew))
        except (ShutdownException, ExternalShutdownException, ConditionReachedException):
            continue  # the loop condition decides
        except Exception as exc:
            on_error(exc)
        changes.notify()


class SpinThread:
    """A daemon thread spinning one executor until :meth:`stop` (or its context shuts down)."""

    def __init__(self, executor, name: str, on_error: ErrorHandler,
                 on_exit: Callable[[], None] | None = None):
        self.executor = executor
        self._stop = StopSignal()
        self._on_error = on_error
        self._on_exit = on_exit
        self.thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> SpinThread:
        action_requests.install()  # a goal sent from another thread must find its response (see there)
        self.thread.start()
        return self

    def _run(self) -> None:
        try:
            spin_until_stopped(self.executor, self._stop, self._on_error)
        finally:
            if self._on_exit is not None:
                self._on_exit()

    @property
    def alive(self) -> bool:
        return self.thread.is_alive()

    def stop(self, timeout: float = 10.0) -> bool:
        """Ask the loop to end, wake the executor and join; True if the thread ended."""
        self._stop.set()
        with contextlib.suppress(Exception):  # the context is already shut down: the loop ends by itself
            self.executor.wake()
        if self.thread is not threading.current_thread() and self.thread.ident is not None:
            self.thread.join(timeout)
        return not self.thread.is_alive()


class RoutedCallbacks(WakeOnce):
    """Executor mix-in: route each callback's output to its node's console; report errors.

    A plain rclpy executor re-raises a callback's exception out of ``spin()``, which
    would end the background thread; here the traceback goes to the node's console
    (through ``router``) and the other nodes keep running. ``wait_for_ready_callbacks`` says which
    node a callback belongs to.
    """

    def _setup_routing(self, console_of_node: Callable, router, on_callback_error: Callable):
        self._console_of_node = console_of_node
        self._router = router
        self._on_callback_error = on_callback_error
        self._current_console = None

    def run_handler(self, handler, node) -> None:
        target = self._console_of_node(node)
        if target is not self._current_console:
            self._router.enter(target)
            self._current_console = target
        handler()
        exc = handler.exception()
        if exc is not None:
            where = node.get_fully_qualified_name() if node is not None else "a task"
            self._on_callback_error(target, where, exc)


class SingleThreaded(OutlivesDestroyedEntities, SingleThreadedExecutor):
    """rclpy's single-threaded executor for the course's threads (:class:`OutlivesDestroyedEntities`)."""


class MultiThreaded(OutlivesDestroyedEntities, MultiThreadedExecutor):
    """rclpy's multi-threaded executor for the course's threads (:class:`OutlivesDestroyedEntities`)."""


class QuietSingleThreadedExecutor(WakeOnce, SingleThreaded):
    """A single-threaded executor for a long-lived thread of the runtime's own (the /rosout reader)."""


class CourseSingleThreadedExecutor(RoutedCallbacks, SingleThreaded):
    """The runtime's default executor: one thread, callbacks routed to their consoles."""

    def __init__(self, context, console_of_node, router, on_callback_error):
        super().__init__(context=context)
        self._setup_routing(console_of_node, router, on_callback_error)


class CourseMultiThreadedExecutor(MultiThreaded):
    """Multi-threaded executor (chapter 02); a callback's error is reported, not raised."""

    def __init__(self, context, num_threads: int, on_callback_error):
        super().__init__(num_threads=num_threads, context=context)
        self._on_callback_error = on_callback_error

    def spin_once_until_future_complete(self, future, timeout_sec=None) -> None:
        try:
            super().spin_once_until_future_complete(future, timeout_sec)
        except (ShutdownException, TimeoutException, ConditionReachedException):
            return
        except Exception as exc:  # raised from a finished callback's future
            self._on_callback_error(None, "a multi-threaded callback", exc)


def plain_executor(kind: str, context, threads: int = 2):
    """rclpy's executor of ``kind`` 'single' or 'multi', with no routing (for measurements that compare
    them); an entity destroyed from another thread is no error (:class:`OutlivesDestroyedEntities`)."""
    if kind == "single":
        return SingleThreaded(context=context)
    return MultiThreaded(num_threads=threads, context=context)


def finish_pending_callbacks(executor) -> None:
    """Let callbacks already handed to a multi-threaded executor's pool finish before destruction.

    rclpy's ``MultiThreadedExecutor.shutdown`` does not wait for its thread pool; a callback
    still queued there would run after its node is destroyed and fail. Its pool and its futures are
    private (``_executor``, ``_futures``: tests/test_rclpy_private_api.py); a rename fails loudly here.
    """
    if not isinstance(executor, MultiThreadedExecutor):
        return
    executor._executor.shutdown(wait=True)
    for task in list(executor._futures):
        if task.done():
            task.exception()  # mark any error as seen


def queued_tasks(executor) -> list:
    """The tasks an executor holds (its callbacks in progress and the coroutines it was given), as
    ``Task`` objects. rclpy 7.1 keeps them in the private ``Executor._tasks`` as (task, entity, node);
    newer releases split it into ``_pending_tasks`` and ``_ready_tasks``. A rename fails loudly with
    what to adapt (tests/test_rclpy_private_api.py checks the pinned release)."""
    if not hasattr(executor, "_tasks"):
        raise AttributeError("rclpy's Executor has no _tasks any more (newer releases: _pending_tasks, "
                             "_ready_tasks): adapt course_helpers.core.executors.queued_tasks")
    tasks = [item[0] if isinstance(item, tuple) else item for item in list(executor._tasks)]
    if isinstance(executor, MultiThreadedExecutor):
        tasks += list(executor._futures)
    return tasks


@contextlib.contextmanager
def spinning_alone(runtime, node_factory: Callable, kind: str = "single", threads: int = 2,
                   thread_name: str = "spin-alone", **kwargs):
    """Build a node in ``runtime``'s context and spin it in an executor of its own during the block.

    Args:
        runtime: the course runtime (its context; its nodes are not touched).
        node_factory: a Node subclass or a function returning a node, called with ``kwargs``.
        kind: 'single' or 'multi' (a MultiThreadedExecutor with ``threads`` threads).
        thread_name: the spinning thread's name.

    Yields:
        The node; nothing else shares its executor, so a measurement is not delayed by the
        notebook's other nodes. Afterwards the executor is shut down, the node destroyed, and the
        first exception a callback raised is raised again.
    """
    node = runtime.build(node_factory, **kwargs)
    executor = plain_executor(kind, runtime.context, threads)
    executor.add_node(node)
    errors: list[BaseException] = []
    spinner = SpinThread(executor, thread_name, errors.append).start()
    try:
        yield node
    finally:
        spinner.stop()
        executor.shutdown(timeout_sec=5)
        finish_pending_callbacks(executor)
        node.destroy_node()
    if errors:
        raise errors[0]
