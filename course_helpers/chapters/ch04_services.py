"""Chapter 04 (services): the deadlock demo and the topic-vs-service latency measurement.

* :class:`Sandbox` gives the deadlock demo a context apart from the kernel's (kept for the process:
  ``core/kept_contexts.py`` says why) and a thread for the executor the notebook wires in it; its
  nodes are torn down even if a callback hangs in ``client.call()``, so the kernel's runtime never
  hangs. :func:`spin_until_answered` runs such an executor and reports whether the caller got its
  answer within a time limit. :class:`IsolatedExecutor` is a sandbox that makes its executor itself
  (the checkers use it).
* :func:`measure_round_trips` times, against a node in a child process, how long a
  caller waits for ``publish()``, a topic message, a topic ping-pong and a service
  call; :func:`plot_round_trips` draws the result.

Everything runs real rclpy nodes over Fast DDS.
"""

from __future__ import annotations

import os
import statistics
import sys
import threading
import time
from dataclasses import dataclass, field

from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import Int64

from course_helpers.core.errors import CourseError, WaitTimeout
from course_helpers.core.executors import SpinThread, plain_executor, queued_tasks
from course_helpers.core.kept_contexts import kept_context
from course_helpers.core.node_hook import build_nodes
from course_helpers.core.runtime import get_runtime
from course_helpers.core.validation import check_namespace
from course_helpers.core.waiting import poll_until, wait_until

DEMO_NAMESPACE = "/deadlock_demo"
ADD_SERVICE = "add_two_ints"
EXECUTOR_KINDS = ("single", "multi")
TEARDOWN_TIMEOUT_S = 3.0  # how long close() keeps releasing stuck calls before it gives up waiting
CLIENT_MODULE = os.path.join("rclpy", "client.py")  # where Client.call() waits for its answer
RELEASE_PERIOD_S = 0.02  # how often close() releases calls (a released callback may call again)


# ---------------------------------------------------------------------- a reference adder
def _add_two_ints_type():
    from course_interfaces.srv import AddTwoInts

    return AddTwoInts


class AdderServer(Node):
    """Offers ``add_two_ints`` (course_interfaces/srv/AddTwoInts) and counts the requests it answered."""

    def __init__(self, name: str = "adder", service: str = ADD_SERVICE, **node_kwargs):
        super().__init__(name, **node_kwargs)
        self.answered = 0
        self.service = self.create_service(_add_two_ints_type(), service, self.on_request)

    def on_request(self, request, response):
        response.sum = request.a + request.b
        self.answered += 1
        return response


# ---------------------------------------------------------------------- the sandbox
class Sandbox:
    """A context apart from the kernel's for nodes that may deadlock, and a thread that spins their executor.

    The notebook wires the executor itself; the sandbox only runs it, and tears everything down
    even if a callback hangs::

        with Sandbox() as sandbox:
            executor = SingleThreadedExecutor(context=sandbox.context)
            caller = BlockingCaller(context=sandbox.context)
            executor.add_node(caller)
            sandbox.spin(executor)
            sandbox.wait_for(lambda: caller.answer is not None, timeout_s=2.0)

    Args:
        namespace: given to every node of the context (a global remapping), so that its services do
            not clash with the notebook's own.

    On exit, any service call still waiting is failed on purpose, which releases a callback stuck
    in ``client.call()``; then the thread is joined and the nodes destroyed. The context itself is
    the process's kept one for the namespace (:func:`~course_helpers.core.kept_contexts.kept_context`):
    its DDS participant outlives the sandbox, because destroying a participant can hang for good.
    Exceptions that callbacks raised while the sandbox ran are in ``errors``.
    """

    def __init__(self, namespace: str = DEMO_NAMESPACE):
        self.namespace = check_namespace(namespace)
        self.errors: list[str] = []
        self.nodes: list[Node] = []
        self.context = None  # an rclpy Context inside the `with` block
        self.executor = None
        self._spinner: SpinThread | None = None
        self._closing = False

    def __enter__(self):
        domain_id = get_runtime().domain.domain_id  # same domain: the kernel can see these nodes
        self.context = kept_context(domain_id, self.namespace)
        self._closing = False
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False

    def spin(self, executor) -> None:
        """Spin ``executor`` (made with ``context=sandbox.context``, its nodes added) in the sandbox's thread.

        Raises :class:`CourseError` outside a ``with`` block, for an executor of another context, or
        when the sandbox spins one already.
        """
        if self.context is None:
            raise CourseError("use the sandbox in a `with` block before spinning in it")
        if executor.context is not self.context:
            raise CourseError("make the executor with context=sandbox.context, so that it spins the "
                              "sandbox's nodes and nothing of the kernel")
        if self.executor is not None:
            raise CourseError("this sandbox spins an executor already: use a new sandbox")
        self.executor = executor
        self.nodes += [node for node in executor.get_nodes() if node not in self.nodes]
        self._spinner = SpinThread(executor, "isolated-executor", self._record_error).start()

    @property
    def spinning(self) -> bool:
        """True while the sandbox's thread spins its executor."""
        return self._spinner is not None and self._spinner.alive

    @property
    def single_threaded(self) -> bool:
        return isinstance(self.executor, SingleThreadedExecutor)

    def waiting_in_a_call(self) -> str:
        """The callback of this single-threaded executor that waits in ``Client.call()``, as
        'node.callback', or '' if none does.

        Such a callback waits for an answer that only this executor's one thread could deliver, and
        that thread is the one waiting: a deadlock, by construction, whatever the machine's speed.
        """
        if not self.single_threaded or self._spinner is None or self._spinner.thread.ident is None:
            return ""
        frame = sys._current_frames().get(self._spinner.thread.ident)
        in_call = False
        while frame is not None:
            code = frame.f_code
            if code.co_name == "call" and code.co_filename.endswith(CLIENT_MODULE):
                in_call = True
            elif in_call and "self" in frame.f_locals and isinstance(frame.f_locals["self"], Node):
                return f"{frame.f_locals['self'].get_name()}.{code.co_name}"
            frame = frame.f_back
        return "a callback" if in_call else ""

    def wait_for(self, predicate, timeout_s: float) -> bool:
        """Wait up to ``timeout_s`` seconds for ``predicate()``; True if it became true."""
        return poll_until(predicate, timeout_s)

    def release_waiting_calls(self) -> int:
        """Cancel every service request a node of the sandbox is still waiting for; returns how many.

        A callback blocked in ``client.call()`` then gets ``None`` back and finishes.
        """
        released = 0
        for node in self.nodes:
            for client in list(node.clients):
                for future in list(client._pending_requests.values()):  # private: test_rclpy_private_api
                    future.cancel()
                    released += 1
        return released

    def close(self) -> None:
        """Release stuck calls, stop the thread and destroy the nodes (the kept context stays)."""
        if self.context is None:
            return
        self._closing = True
        if self._spinner is not None:
            self._spinner.stop(timeout=0)  # ask the loop to end; a callback may still be stuck in a call
            poll_until(self._released_and_idle, TEARDOWN_TIMEOUT_S, RELEASE_PERIOD_S)
            if isinstance(self.executor, MultiThreadedExecutor):  # its worker threads: private, as above
                self.executor._executor.shutdown(wait=not self._callbacks_running())
        if self.executor is not None:
            self.nodes += [node for node in self.executor.get_nodes() if node not in self.nodes]
            for node in self.nodes:
                self.executor.remove_node(node)
            self.executor.shutdown(timeout_sec=1.0)
        for node in self.nodes:  # never the kept context's keeper: no executor spins it
            node.destroy_node()
        self.nodes.clear()
        if self.executor is not None:
            self._collect_task_errors()
        self.context, self.executor, self._spinner = None, None, None

    def _released_and_idle(self) -> bool:
        """Release waiting calls (a released callback may block again in another call); True once
        the spin thread has ended and no callback runs."""
        self.release_waiting_calls()
        return not self._spinner.alive and not self._callbacks_running()

    def _record_error(self, error: BaseException) -> None:
        """A callback raised: remember it, unless the teardown caused it (a released call)."""
        if not self._closing:
            self.errors.append(f"{type(error).__name__}: {error}")

    def _callbacks_running(self) -> bool:
        """True while a callback of the multi-threaded executor's workers has not finished."""
        return isinstance(self.executor, MultiThreadedExecutor) and any(
            not future.done() for future in list(self.executor._futures))  # private, as above

    def _collect_task_errors(self) -> None:
        """Read the errors of tasks left behind, so rclpy does not print them later at random.

        A callback that was cut short by the teardown can end with an error nobody
        asked for; rclpy prints such errors when the task is garbage-collected, which
        would land in whatever cell runs then.
        """
        for task in queued_tasks(self.executor):
            if task.done() and task.exception() is not None:
                self.errors.append(f"{type(task.exception()).__name__}: {task.exception()}")


class IsolatedExecutor(Sandbox):
    """A :class:`Sandbox` that makes its executor itself and builds nodes into it (the checkers' way)::

        with IsolatedExecutor('single', namespace='/relay_check') as box:
            server = box.add(AdderServer)

    Args:
        executor: 'single' or 'multi' (a SingleThreadedExecutor or a MultiThreadedExecutor).
        namespace: as for :class:`Sandbox`.
        threads: worker threads of the multi-threaded executor.
    """

    def __init__(self, executor: str = "single", namespace: str = DEMO_NAMESPACE, threads: int = 4):
        if executor not in EXECUTOR_KINDS:
            raise CourseError(f"executor must be 'single' or 'multi', got {executor!r}")
        super().__init__(namespace)
        self.kind = executor
        self.threads = threads

    def add(self, node_class, *args, **kwargs) -> Node:
        """Build ``node_class(*args, **kwargs)`` in this sandbox's context and spin it; returns the node.

        The class may call ``super().__init__('name')`` without a context: the node joins
        the sandbox's context anyway. Raises :class:`CourseError` outside a ``with`` block or
        if the class builds no Node.
        """
        if self.context is None:
            raise CourseError("use IsolatedExecutor in a `with` block before adding nodes")
        node = build_nodes(self.context, node_class, *args, **kwargs)
        if not isinstance(node, Node):
            raise CourseError(f"{getattr(node_class, '__name__', node_class)!r} did not build an rclpy Node")
        if self.executor is None:
            self.spin(plain_executor(self.kind, self.context, self.threads))
        self.nodes.append(node)
        self.executor.add_node(node)
        return node


# ---------------------------------------------------------------------- the deadlock demo
@dataclass
class DeadlockOutcome:
    """What :func:`spin_until_answered` saw; ``str()`` gives a one-line verdict."""

    caller: str
    executor: str
    completed: bool
    answer: object
    timeout_s: float
    server_answered: int
    errors: list[str] = field(default_factory=list)

    @property
    def deadlocked(self) -> bool:
        return not self.completed

    def __str__(self) -> str:
        where = f"{self.caller} on a {self.executor}-threaded executor"
        if self.completed:
            return f"completed: {where} got its answer {self.answer!r}"
        served = ("the server never even saw the request" if self.server_answered == 0 else
                  "the server answered, but the reply was never taken")
        return (f"deadlocked: the call did not return within {self.timeout_s:g} s "
                f"({where}; {served})")

    def _repr_pretty_(self, printer, cycle):
        printer.text(str(self))


def spin_until_answered(sandbox: Sandbox, executor, caller, server, timeout_s: float = 2.0,
                        answer_attribute: str = "answer") -> DeadlockOutcome:
    """Spin ``executor`` in ``sandbox`` until ``caller`` has its answer, for at most ``timeout_s`` seconds.

    Args:
        sandbox: the :class:`Sandbox` whose context the executor and both nodes were made with.
        executor: spins ``caller`` and ``server`` (the notebook wired it).
        caller: a node that asks ``add_two_ints`` from one of its callbacks and stores the sum in
            ``caller.answer`` (``answer_attribute`` names another attribute).
        server: the :class:`AdderServer` it asks; it counts the requests it answered.
        timeout_s: 0.1 to 30. An answer still missing then is a deadlock: leaving the ``with`` block
            unblocks and destroys everything, and the kernel's runtime is untouched.

    Returns a :class:`DeadlockOutcome`; raises :class:`CourseError` for a bad timeout.
    """
    if isinstance(timeout_s, bool) or not isinstance(timeout_s, (int, float)) or not 0.1 <= timeout_s <= 30:
        raise CourseError(f"timeout_s must be a number of seconds from 0.1 to 30, got {timeout_s!r}")
    sandbox.spin(executor)
    completed = sandbox.wait_for(lambda: getattr(caller, answer_attribute, None) is not None, timeout_s)
    kind = "single" if sandbox.single_threaded else "multi"
    return DeadlockOutcome(type(caller).__name__, kind, completed, getattr(caller, answer_attribute, None),
                           timeout_s, server.answered, sandbox.errors)


# ---------------------------------------------------------------------- topics vs services
class LatencyEcho(Node):
    """Echoes ``latency/ping`` to ``latency/pong`` and answers ``latency/add_two_ints`` (child process)."""

    def __init__(self, name: str = "latency_echo"):
        super().__init__(name)
        self.pong = self.create_publisher(Int64, "latency/pong", 10)
        self.ping = self.create_subscription(Int64, "latency/ping", self.pong.publish, 10)
        self.adder = self.create_service(_add_two_ints_type(), "latency/add_two_ints", self.on_add)

    def on_add(self, request, response):
        response.sum = request.a + request.b
        return response


LATENCY_KINDS = {
    "publish": "topic: publish() returns",
    "topic_round_trip": "topic: ping -> pong round trip",
    "service_round_trip": "service: request -> response",
}


@dataclass
class RoundTrips:
    """Samples in seconds per kind (see ``LATENCY_KINDS``), measured by :func:`measure_round_trips`."""

    samples: dict[str, list[float]]

    def median_us(self, kind: str) -> float:
        """Median of one kind in microseconds."""
        if kind not in self.samples:
            raise CourseError(f"kind must be one of {', '.join(self.samples)}, got {kind!r}")
        return statistics.median(self.samples[kind]) * 1e6

    def table(self) -> str:
        """Medians as an aligned text table (varies run to run: print it in an ignored cell)."""
        return "\n".join(f"{LATENCY_KINDS[k]:<40} median {self.median_us(k):8.1f} us"
                         for k in self.samples)


HANDSHAKE_SEQ = -1  # the ping that proves both directions matched; its echoes are not timed
HANDSHAKE_PERIOD_S = 0.1  # s; how often the handshake ping is sent again until one is echoed


def _echoed_once(ping, echoed: threading.Event, timeout: float) -> None:
    """Send the handshake ping every :data:`HANDSHAKE_PERIOD_S` until one comes back.

    The probe seeing the echo node's endpoints does not mean the echo node's ``pong`` writer has
    matched the probe's reader yet (each side learns of the other in its own discovery message),
    and an echo published before that match is dropped. One echo that arrives proves the whole
    loop is matched; raises :class:`WaitTimeout` if none comes within ``timeout`` seconds.
    """
    def echoed_or_ping_again() -> bool:
        if echoed.is_set():
            return True
        ping.publish(Int64(data=HANDSHAKE_SEQ))
        return False

    wait_until(echoed_or_ping_again, timeout, "the echo node to echo a handshake ping",
               period=HANDSHAKE_PERIOD_S, wake_on=None)


def measure_round_trips(rt=None, samples: int = 200, timeout_s: float = 10.0) -> RoundTrips:
    """Time topics against a service, with the echo node in a child process.

    First a handshake: pings until one is echoed, and one service call, neither timed, so that
    every timed message goes over a matched pair. Then, for each sample, the notebook side (a
    probe node in the kernel) publishes one message on ``latency/ping`` and waits for the echo of
    that very message on ``latency/pong``, then calls ``latency/add_two_ints`` and waits for the
    response. Recorded: how long ``publish()`` blocked the caller, the topic round trip (ping out,
    pong back) and the service round trip (request out, response back). The child process and
    the probe are removed afterwards.

    Args:
        rt: the runtime (default: this kernel's).
        samples: how many samples of each kind, 10 to 5000.
        timeout_s: how long to wait for the handshake, for one echo or for one response [s]. Over a
            matched reliable pair every echo comes; a slow one on a busy machine is just a slow
            sample (the medians hardly move), so this only catches an echo node that stopped.

    Returns a :class:`RoundTrips`; raises :class:`WaitTimeout` if the handshake, an echo or a
    response does not come.
    """
    if isinstance(samples, bool) or not isinstance(samples, int) or not 10 <= samples <= 5000:
        raise CourseError(f"samples must be a whole number from 10 to 5000, got {samples!r}")
    if isinstance(timeout_s, bool) or not isinstance(timeout_s, (int, float)) or not timeout_s > 0:
        raise CourseError(f"timeout_s must be a number of seconds above 0, got {timeout_s!r}")
    rt = rt or get_runtime()
    add_two_ints = _add_two_ints_type()
    rt.spawn("latency_echo", LatencyEcho, wait_for="/latency_echo")
    probe = rt.node("latency_probe")
    try:
        awaited = [HANDSHAKE_SEQ]  # the sequence number whose echo is awaited
        pong_seen = threading.Event()

        def on_pong(msg: Int64) -> None:
            if msg.data == awaited[0]:  # a late echo of an earlier ping is not this one
                pong_seen.set()

        ping = probe.create_publisher(Int64, "latency/ping", 10)
        probe.create_subscription(Int64, "latency/pong", on_pong, 10)
        client = probe.create_client(add_two_ints, "latency/add_two_ints")
        rt.wait_until(lambda: ping.get_subscription_count() >= 1 and client.service_is_ready(), timeout_s,
                      "the echo node's ping subscription and service")
        _echoed_once(ping, pong_seen, timeout_s)
        rt.wait_for_future(client.call_async(add_two_ints.Request(a=HANDSHAKE_SEQ, b=1)), timeout_s,
                           "the service response to the handshake request")
        result = {kind: [] for kind in LATENCY_KINDS}
        for seq in range(samples):
            pong_seen.clear()
            awaited[0] = seq
            start = time.perf_counter()
            ping.publish(Int64(data=seq))
            published = time.perf_counter()
            if not pong_seen.wait(timeout_s):
                raise WaitTimeout(f"no pong within {timeout_s:g} s for ping {seq} (the handshake had "
                                  "succeeded: has the echo node stopped?)")
            echoed = time.perf_counter()
            result["publish"].append(published - start)
            result["topic_round_trip"].append(echoed - start)
            start = time.perf_counter()
            rt.wait_for_future(client.call_async(add_two_ints.Request(a=seq, b=1)), timeout_s,
                               f"the service response to request {seq}")
            result["service_round_trip"].append(time.perf_counter() - start)
    finally:
        rt.remove(probe)
        rt.stop_child("latency_echo")
    return RoundTrips(result)


def plot_round_trips(trips: RoundTrips):
    """Box plot (log scale, microseconds) of the three kinds of :class:`RoundTrips`; returns the Figure."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, NullFormatter

    kinds = list(trips.samples)
    data = [[s * 1e6 for s in trips.samples[k]] for k in kinds]
    fig, ax = plt.subplots(figsize=(8, 3.6))
    colours = ["#94a3b8", "#2563eb", "#f97316"]
    box = ax.boxplot(data, vert=False, patch_artist=True, showfliers=False, widths=0.6,
                     medianprops={"color": "black", "linewidth": 1.5})
    for patch, colour in zip(box["boxes"], colours, strict=False):
        patch.set_facecolor(colour)
    ax.set_yticks(range(1, len(kinds) + 1), [LATENCY_KINDS[k] for k in kinds])
    ax.set_xscale("log")
    ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _pos: f"{value:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("time the caller waits [µs], log scale")
    ax.invert_yaxis()
    ax.grid(axis="x", which="both", alpha=0.3)
    right_ends = []
    for row, values in enumerate(data, start=1):
        whisker_end = max(box["whiskers"][2 * row - 1].get_xdata())
        right_ends.append(whisker_end)
        ax.annotate(f"median {statistics.median(values):.0f} µs", (whisker_end, row), xytext=(6, 0),
                    textcoords="offset points", va="center", fontsize=9)
    ax.set_xlim(right=max(right_ends) * 6)
    ax.set_title(f"Topic vs service: what the caller waits for ({len(data[0])} samples each)",
                 fontsize=10)
    fig.tight_layout()
    return fig
