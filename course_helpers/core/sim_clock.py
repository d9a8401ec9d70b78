"""A clock and an executor the caller owns: how a checker judges timer logic the same way on any machine.

rosbag2's player owns the time of the nodes it feeds: it publishes ``/clock``, and a node with the
parameter ``use_sim_time`` set to true reads its time, and runs its timers, from there. A
:class:`SimClock` does the same for a checker, and goes one step further: it also owns the executor
that runs the nodes under test. Every step of time is then one exact sequence:

1. publish ``/clock`` with the new time;
2. run every callback that is ready, until none is (:meth:`SimClock.settle`): the ``/clock``
   subscription moves each node's clock, timers that fell due fire, messages published by one
   driven node reach the others.

Nothing here waits on the wall clock but :meth:`SimClock.wait_matched`: two endpoints of one
participant match a moment after they are created. Once they have, publishers and subscriptions of
one context hand each message over inside ``publish()`` (Fast DDS's intra-process delivery), so after
a settle every message sent has been received and every callback it caused has run: "nothing
arrived" is exact, without a window to sleep through. A 10 s scenario takes a fraction of a second,
whatever the load.

Time starts at :data:`START_S` (a ROS time far from both zero and the wall clock, so a node that reads
``time.time()`` or ``time.monotonic()`` instead of its own clock is seen at once).
"""

from __future__ import annotations

from rclpy.executors import TimeoutException
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy

from course_helpers.core.errors import CourseError
from course_helpers.core.executors import SingleThreaded
from course_helpers.core.node_hook import outside_builds
from course_helpers.core.waiting import wait_until

CLOCK_TOPIC = "/clock"
START_S = 1000.0  # s of ROS time when a SimClock starts
MATCH_TIMEOUT_S = 30.0  # s; bounds a hang only: endpoints of one participant match in milliseconds
MAX_CALLBACKS_PER_SETTLE = 10_000  # more callbacks than this after one step: they never go quiet
DEFAULT_STEP_S = 0.01  # s; how far :meth:`SimClock.advance` moves time per step


class SimClock:
    """Publishes ``/clock`` in ``runtime``'s context (or in ``context``) and spins the nodes it drives,
    only when told.

    ``clock = SimClock(rt)``; ``node = clock.drive(rt.build(MyNode))``; ``clock.advance(2.0)``;
    ``clock.close()``. The driven nodes are not spun by the runtime's executor; the caller destroys
    them. Callback errors are kept in :attr:`errors` (the step goes on).
    """

    def __init__(self, runtime=None, start_s: float = START_S, name: str = "_course_sim_clock",
                 context=None):
        from rclpy.node import Node
        from rosgraph_msgs.msg import Clock

        if (runtime is None) == (context is None):
            raise CourseError("give SimClock either the runtime or a context, not both")
        context = context if context is not None else runtime.context
        self._clock_type = Clock
        with outside_builds():  # the clock's own node belongs to no build of the caller's
            self.node = Node(name, context=context, enable_rosout=False, start_parameter_services=False)
        self._publisher = self.node.create_publisher(
            Clock, CLOCK_TOPIC, QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))
        self._executor = SingleThreaded(context=context)
        self._ns = round(start_s * 1e9)
        self.errors: list[BaseException] = []
        self.driven: list = []

    @property
    def now_s(self) -> float:
        """The ROS time the driven nodes see, in seconds."""
        return self._ns / 1e9

    def drive(self, node):
        """Put ``node`` on this clock (``use_sim_time`` true) and into this clock's executor; return it.

        The node must not be spun elsewhere (build it with ``rt.build``, not ``rt.add``).
        """
        node.set_parameters([Parameter("use_sim_time", Parameter.Type.BOOL, True)])
        self._executor.add_node(node)
        self.driven.append(node)
        self.wait_matched()
        self._publish()
        self.settle()
        return node

    def wait_matched(self, timeout: float = MATCH_TIMEOUT_S) -> None:
        """Wait until every publisher of the driven nodes (and ``/clock``'s) has matched every
        subscription the graph lists on its topic: call it after creating endpoints, before stepping.
        Raises WaitTimeout naming the topic that stayed unmatched."""
        publishers = [self._publisher, *(p for node in self.driven for p in node.publishers)]

        def unmatched() -> list[str]:
            return [p.topic_name for p in publishers
                    if p.get_subscription_count() < self.node.count_subscribers(p.topic_name)]

        wait_until(lambda: not unmatched(), timeout,
                   f"the publishers on {', '.join(sorted(set(unmatched()))) or 'every topic'} to match "
                   "their subscriptions")

    def settle(self) -> int:
        """Run every ready callback of the driven nodes until none is ready; how many ran.

        rclpy's executor hands out the callbacks one wait's worth at a time, and with a zero timeout
        it ends each batch with TimeoutException, even when it handed some out; so batches follow
        each other until one makes no progress. A batch that only resumed coroutines still waiting
        (an ``async`` callback awaiting a future that a later step completes: rclpy hands those out
        before every wait) made none: only another callback, or time, can complete what they await.
        Raises CourseError if the callbacks never go quiet (more than :data:`MAX_CALLBACKS_PER_SETTLE`).
        """
        count = 0
        while True:
            progress = False
            while True:
                try:
                    handler, _entity, _node = self._executor.wait_for_ready_callbacks(timeout_sec=0)
                except TimeoutException:
                    break
                handler()
                count += 1
                if handler.done():
                    progress = True
                    if handler.exception() is not None:
                        self.errors.append(handler.exception())
                if count > MAX_CALLBACKS_PER_SETTLE:
                    raise CourseError(
                        f"the nodes' callbacks did not go quiet: more than {MAX_CALLBACKS_PER_SETTLE} ran "
                        "after one step of the clock (a callback that triggers itself, such as a "
                        "subscription that publishes to its own topic?)")
            if not progress:
                return count

    def step(self, seconds: float) -> None:
        """Move time forward by ``seconds`` in one jump, then settle."""
        if not seconds >= 0:
            raise CourseError(f"time moves forward only: seconds must be >= 0, got {seconds!r}")
        self._ns += round(seconds * 1e9)
        self._publish()
        self.settle()

    def advance(self, seconds: float, step_s: float = DEFAULT_STEP_S, between=None) -> None:
        """Move time forward by ``seconds`` in steps of ``step_s``, settling after each; ``between()``,
        if given, is called after every step (a checker publishes its inputs there)."""
        if not step_s > 0:
            raise CourseError(f"step_s must be > 0, got {step_s!r}")
        end = self._ns + round(seconds * 1e9)
        while self._ns < end:
            self.step(min(step_s, (end - self._ns) / 1e9))
            if between is not None:
                between()
                self.settle()

    def advance_until(self, predicate, seconds: float, step_s: float = DEFAULT_STEP_S) -> bool:
        """Move time forward in steps of ``step_s`` until ``predicate()`` is true (checked once before
        moving, then after every step) or ``seconds`` have passed; True if it came true."""
        if not step_s > 0:
            raise CourseError(f"step_s must be > 0, got {step_s!r}")
        self.settle()
        end = self._ns + round(seconds * 1e9)
        while not predicate():
            if self._ns >= end:
                return False
            self.step(min(step_s, (end - self._ns) / 1e9))
        return True

    def _publish(self) -> None:
        message = self._clock_type()
        message.clock.sec, message.clock.nanosec = divmod(self._ns, 1_000_000_000)
        self._publisher.publish(message)

    def close(self) -> None:
        """Take the driven nodes out of this executor (the caller destroys them) and end the clock."""
        for node in self.driven:
            self._executor.remove_node(node)
        self.driven.clear()
        self._executor.shutdown(timeout_sec=0)
        self.node.destroy_node()
