"""Benchmark: small-message throughput through the course runtime vs plain rclpy, and idle CPU.

Run with ``make bench`` or ``.venv/bin/python benchmarks/executor_throughput.py``.

Throughput: a publisher thread floods ``std_msgs/String`` for a few seconds while a
subscriber counts deliveries in a background SingleThreadedExecutor. The same
measurement runs through plain rclpy (its own context, ``executor.spin()`` in a
thread: the baseline) and through the course runtime (``rt.add``), alternating,
in this one run. The script prints messages per second for each and the ratio
course / plain (goal: >= 0.95).

The same comparison then runs inside a real Jupyter kernel, where the runtime
also routes every callback's output to its cell and subscribes to ``/rosout`` to
show node logs there (``KERNEL_ROUNDS`` alternating rounds).

Idle CPU: a fresh process starts the runtime with two idle nodes and measures
its CPU time over 10 s (goal: <= 1% of one core).
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import textwrap
import threading
import time

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import String

FLOOD_S = 3.0  # seconds of flooding per measurement
ROUNDS = 5  # alternating rounds of each variant
KERNEL_ROUNDS = 3  # alternating rounds inside a Jupyter kernel
IDLE_S = 10.0  # seconds of idle CPU measurement


class Counter(Node):
    """Counts the messages it receives."""

    def __init__(self, name: str = "bench_counter", context=None):
        super().__init__(name, context=context)
        self.count = 0
        self.subscription = self.create_subscription(String, "bench", self.on_message, 100)

    def on_message(self, _msg: String) -> None:
        self.count += 1


class Flooder(Node):
    """Publishes as fast as it can from a plain thread while ``running`` is set."""

    def __init__(self, name: str = "bench_flooder", context=None):
        super().__init__(name, context=context)
        self.publisher = self.create_publisher(String, "bench", 100)


def flood_and_count(flooder: Flooder, counter: Counter, wait_matched) -> float:
    """Flood for FLOOD_S seconds; return deliveries per second."""
    wait_matched()
    msg = String(data="x" * 16)
    stop = threading.Event()

    def publish_loop():
        while not stop.is_set():
            flooder.publisher.publish(msg)

    thread = threading.Thread(target=publish_loop)
    thread.start()
    time.sleep(0.5)  # warm up
    start_count, start = counter.count, time.perf_counter()
    time.sleep(FLOOD_S)
    delivered, elapsed = counter.count - start_count, time.perf_counter() - start
    stop.set()
    thread.join()
    return delivered / elapsed


def plain_rclpy_rate() -> float:
    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    executor = SingleThreadedExecutor(context=context)
    counter, flooder = Counter(context=context), Flooder(context=context)
    executor.add_node(counter)
    executor.add_node(flooder)
    spin = threading.Thread(target=executor.spin)
    spin.start()
    try:
        return flood_and_count(flooder, counter,
                               lambda: _wait(lambda: flooder.publisher.get_subscription_count() > 0))
    finally:
        executor.shutdown()
        context.try_shutdown()  # ends spin()
        spin.join()
        counter.destroy_node()
        flooder.destroy_node()


def course_runtime_rate() -> float:
    from course_helpers import get_runtime

    rt = get_runtime()
    counter, flooder = rt.add(Counter), rt.add(Flooder)
    try:
        return flood_and_count(flooder, counter,
                               lambda: _wait(lambda: flooder.publisher.get_subscription_count() > 0))
    finally:
        rt.remove_all()


def idle_cpu_percent() -> float:
    code = textwrap.dedent(f"""
        import os, time
        from course_helpers import get_runtime
        from course_helpers.nodes import Listener
        rt = get_runtime()
        rt.add(Listener, name="idle_a")
        rt.add(Listener, name="idle_b", topic="other")
        time.sleep(1.0)  # let discovery settle
        t0, c0 = time.monotonic(), sum(os.times()[:2])
        time.sleep({IDLE_S})
        t1, c1 = time.monotonic(), sum(os.times()[:2])
        print(100.0 * (c1 - c0) / (t1 - t0))
        rt.stop()
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def in_kernel_rates() -> tuple[list[float], list[float]]:
    """Run KERNEL_ROUNDS alternating rounds inside a fresh Jupyter kernel; return (plain, course)."""
    from jupyter_client.manager import start_new_kernel

    code = textwrap.dedent(f"""
        import json
        import benchmarks.executor_throughput as bench
        plain, course = [], []
        for _ in range({KERNEL_ROUNDS}):
            plain.append(bench.plain_rclpy_rate())
            course.append(bench.course_runtime_rate())
        print('RATES', json.dumps([plain, course]))
    """)
    manager, client = start_new_kernel(kernel_name="python3")
    lines: list[str] = []

    def on_output(msg):
        if msg["msg_type"] == "stream" and msg["content"]["name"] == "stdout":
            lines.append(msg["content"]["text"])

    try:
        reply = client.execute_interactive(code, timeout=600, output_hook=on_output)
        if reply["content"]["status"] != "ok":
            raise RuntimeError(f"the kernel run failed: {reply['content'].get('evalue')}")
    finally:
        client.stop_channels()
        manager.shutdown_kernel(now=False)
    plain, course = json.loads("".join(lines).split("RATES", 1)[1])
    return plain, course


def _wait(predicate, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError("publisher and subscriber did not match")
        time.sleep(0.01)


def main() -> None:
    plain, course = [], []
    for round_ in range(ROUNDS):
        plain.append(plain_rclpy_rate())
        course.append(course_runtime_rate())
        print(f"round {round_ + 1}: plain rclpy {plain[-1]:8.0f} msg/s   "
              f"course runtime {course[-1]:8.0f} msg/s", flush=True)
    ratio = statistics.median(course) / statistics.median(plain)
    best_ratio = max(course) / max(plain)
    print(f"median: plain rclpy {statistics.median(plain):.0f} msg/s, "
          f"course runtime {statistics.median(course):.0f} msg/s")
    print(f"throughput ratio course/plain = {ratio:.3f} (median of {ROUNDS} rounds; goal >= 0.95)")
    print(f"best-round ratio course/plain = {best_ratio:.3f} (least disturbed by other load)")
    kernel_plain, kernel_course = in_kernel_rates()
    kernel_ratio = statistics.median(kernel_course) / statistics.median(kernel_plain)
    print(f"in a Jupyter kernel: plain rclpy {statistics.median(kernel_plain):.0f} msg/s, course runtime "
          f"{statistics.median(kernel_course):.0f} msg/s (output routing and /rosout logs on)")
    print(f"in-kernel throughput ratio course/plain = {kernel_ratio:.3f} "
          f"(median of {KERNEL_ROUNDS} rounds; goal >= 0.95)")
    cpu = idle_cpu_percent()
    print(f"idle CPU of a started runtime with two idle nodes over {IDLE_S:.0f} s: "
          f"{cpu:.2f}% of one core (goal <= 1%)")
    from course_helpers import shutdown_runtime

    shutdown_runtime()


if __name__ == "__main__":
    main()
