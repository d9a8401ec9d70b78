"""The QoS lab's engine (chapter 08, notebook ``08b_qos_lab``): one real experiment per call.

``run_experiment(config)`` measures what a QoS profile does to a stream of samples:

* the publisher runs in a CHILD PROCESS (``make_lab_publisher``), so every sample
  crosses a real Fast DDS transport (shared memory or UDP loopback); inside one
  process Fast DDS would hand samples over intra-process and nothing could be lost;
* the subscriber runs in the kernel's runtime and counts, in a cheap callback,
  what arrives, the gaps in the DDS ``publication_sequence_number`` of each sample,
  the DDS ``message_lost`` event, and the latency from the send stamp;
* the child counts ``publish()`` failures (``RCLError`` when a KEEP_ALL writer's
  history is full) and reports them in a summary line, so back-pressure is an
  error counted per run, not a crash.

Nothing is simulated: if a configuration loses nothing, the result says so. The
widget panel (``qos_lab.py``) and the plots (``lab_plots.py``) are thin layers on
top of this module; ``PRESETS`` holds the lab's one-click scenarios.
"""

from __future__ import annotations

import json
import math
import os
import threading
import time
from array import array
from dataclasses import asdict, dataclass, field, replace

from course_interfaces.msg import ExperimentSample
from rclpy._rclpy_pybind11 import RCLError
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSDurabilityPolicy, QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy

from course_helpers.core.errors import CourseError

# ---------------------------------------------------------------------- limits and names
RELIABILITY = ("reliable", "best_effort")
DURABILITY = ("volatile", "transient_local")
HISTORY = ("keep_last", "keep_all")
TRANSPORTS = {
    "shm": "shared memory (what Fast DDS uses between processes on one machine)",
    "udp": "UDP through the loopback interface only (as between two machines)",
}
MAX_RATE_HZ = 5000.0
MAX_PAYLOAD_BYTES = 4 * 1024 * 1024  # 4 MiB
MIN_DURATION_S, MAX_DURATION_S = 0.1, 20.0
MAX_SAMPLES = 40_000  # rate x duration
MAX_DEPTH = 1000
MAX_PROCESSING_MS = 200.0
MAX_KEEP_ALL_BYTES = 512 * 1024 * 1024  # a KEEP_ALL writer may hold every sample in memory

CHILD_LABEL = "qos_lab_publisher"
PUBLISHER_NODE = "qos_lab_publisher"
SUBSCRIBER_NODE = "qos_lab_subscriber"
PROGRESS_TAG = "QOS_LAB_PROGRESS "
SUMMARY_TAG = "QOS_LAB_SUMMARY "

MATCH_SETTLE_S = 0.2  # the publisher waits this long once matched, so both sides know each other
_MATCH_TIMEOUT_S = 15.0  # child start (Python + rclpy import) plus discovery
_IDLE_END_S = 0.5  # after the publisher is done, end when nothing arrived for this long
_RELIABLE_IDLE_END_S = 3.5  # the same for reliable: longer than Fast DDS's 3 s heartbeat period
_LATE_JOIN_LISTEN_S = 1.0  # a matched late joiner listens this long after its last sample
_DRAIN_LIMIT_S = 2.0  # after the publisher is done, wait at most this long (x3 for reliable)


# ---------------------------------------------------------------------- configuration
@dataclass(frozen=True)
class ExperimentConfig:
    """One lab configuration: QoS of both ends, the load, and the transport.

    reliability: 'reliable' | 'best_effort'; durability: 'volatile' | 'transient_local';
    history: 'keep_last' (uses ``depth``) | 'keep_all' (``depth`` must be None: KEEP_ALL
    keeps every sample until it is acknowledged, so a depth would mean nothing).
    rate_hz: samples per second the publisher sends; payload_bytes: size of each
    sample's filler; processing_ms: how long the subscriber's callback works on each
    sample; transport: 'shm' (Fast DDS default, shared memory) | 'udp' (UDP loopback only);
    duration_s: how long the publisher sends (it sends ``rate_hz * duration_s`` samples);
    late_joiner: the subscriber is created only after the publisher has sent everything.
    """

    reliability: str = "reliable"
    durability: str = "volatile"
    history: str = "keep_last"
    depth: int | None = 10
    rate_hz: float = 100.0
    payload_bytes: int = 1024
    processing_ms: float = 0.0
    transport: str = "shm"
    duration_s: float = 2.0
    late_joiner: bool = False
    label: str = ""

    def __post_init__(self):
        _check_choice("reliability", self.reliability, RELIABILITY)
        _check_choice("durability", self.durability, DURABILITY)
        _check_choice("history", self.history, HISTORY)
        _check_choice("transport", self.transport, tuple(TRANSPORTS))
        if self.history == "keep_all":
            if self.depth is not None:
                raise CourseError(
                    f"depth={self.depth!r} with history='keep_all': KEEP_ALL keeps every sample "
                    "until every reader has it, so a depth means nothing. Pass depth=None with "
                    "'keep_all', or use history='keep_last' with a depth of 1.."
                    f"{MAX_DEPTH}.")
        elif (isinstance(self.depth, bool) or not isinstance(self.depth, int)
              or not 1 <= self.depth <= MAX_DEPTH):
            raise CourseError(f"depth must be a whole number from 1 to {MAX_DEPTH} with "
                              f"history='keep_last', got {self.depth!r}")
        _check_number("rate_hz", self.rate_hz, 1.0, MAX_RATE_HZ, "samples per second")
        if (isinstance(self.payload_bytes, bool) or not isinstance(self.payload_bytes, int)
                or not 0 <= self.payload_bytes <= MAX_PAYLOAD_BYTES):
            raise CourseError(f"payload_bytes must be a whole number from 0 to {MAX_PAYLOAD_BYTES} "
                              f"(4 MiB), got {self.payload_bytes!r}")
        _check_number("processing_ms", self.processing_ms, 0.0, MAX_PROCESSING_MS,
                      "milliseconds per sample")
        _check_number("duration_s", self.duration_s, MIN_DURATION_S, MAX_DURATION_S, "seconds")
        if self.count > MAX_SAMPLES:
            raise CourseError(
                f"rate_hz x duration_s = {self.count} samples; the lab allows at most {MAX_SAMPLES} "
                "per run. Lower the rate or the duration.")
        if self.history == "keep_all" and self.count * self.payload_bytes > MAX_KEEP_ALL_BYTES:
            raise CourseError(
                f"KEEP_ALL may hold every unacknowledged sample in memory: {self.count} samples x "
                f"{self.payload_bytes} bytes is more than {MAX_KEEP_ALL_BYTES // 2**20} MiB. "
                "Lower the rate, the duration or the payload, or use 'keep_last'.")
        if not isinstance(self.late_joiner, bool):
            raise CourseError(f"late_joiner must be True or False, got {self.late_joiner!r}")
        if not isinstance(self.label, str):
            raise CourseError(f"label must be a string, got {self.label!r}")

    @property
    def count(self) -> int:
        """How many samples the publisher sends: ``rate_hz * duration_s``, at least 1."""
        return max(1, round(self.rate_hz * self.duration_s))

    def with_changes(self, **changes) -> ExperimentConfig:
        """A copy with some fields changed (validated again)."""
        return replace(self, **changes)

    def describe(self) -> str:
        """A short human label: 'best_effort, keep_last 10, 400 Hz x 1 MiB, shm'."""
        if self.label:
            return self.label
        history = "keep_all" if self.history == "keep_all" else f"keep_last {self.depth}"
        parts = [self.reliability, self.durability, history,
                 f"{_fmt_rate(self.rate_hz)} x {format_bytes(self.payload_bytes)}"]
        if self.processing_ms:
            parts.append(f"{self.processing_ms:g} ms/sample")
        parts.append(self.transport)
        if self.late_joiner:
            parts.append("late joiner")
        return ", ".join(parts)

    def qos_dict(self) -> dict:
        """The QoS part, as JSON values for the child process."""
        return {"reliability": self.reliability, "durability": self.durability,
                "history": self.history, "depth": self.depth}


def _check_choice(name, value, allowed):
    if value not in allowed:
        raise CourseError(f"{name} must be one of {', '.join(repr(a) for a in allowed)}; got {value!r}")


def _check_number(name, value, low, high, unit):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CourseError(f"{name} must be a number from {low:g} to {high:g} {unit}, got {value!r}")
    if not low <= value <= high:
        raise CourseError(f"{name} must be from {low:g} to {high:g} {unit}, got {value:g}")


def format_bytes(n: int) -> str:
    """'512 B', '64 KiB', '1 MiB'."""
    for unit, size in (("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:g} {unit}"
    return f"{n} B"


def _fmt_rate(rate):
    return f"{rate:g} Hz"


def make_qos(qos: dict):
    """A rclpy ``QoSProfile`` from the lab's QoS dict (``ExperimentConfig.qos_dict()``)."""
    reliability = {"reliable": QoSReliabilityPolicy.RELIABLE,
                   "best_effort": QoSReliabilityPolicy.BEST_EFFORT}[qos["reliability"]]
    durability = {"volatile": QoSDurabilityPolicy.VOLATILE,
                  "transient_local": QoSDurabilityPolicy.TRANSIENT_LOCAL}[qos["durability"]]
    if qos["history"] == "keep_all":
        return QoSProfile(history=QoSHistoryPolicy.KEEP_ALL, reliability=reliability,
                          durability=durability)
    return QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=qos["depth"],
                      reliability=reliability, durability=durability)


# ---------------------------------------------------------------------- the publisher (child)
class LabPublisher(Node):
    """Publishes ``count`` ExperimentSample messages at ``rate_hz`` with a timer.

    Each sample carries a sequence number, the send time (ns, this machine's clock)
    and ``payload_bytes`` of filler. Sending starts once the subscriber is matched
    (``wait_for_subscriber``) or, for a late joiner, once this process has discovered
    the kernel (``wait_for_node``). The timer ticks at the rate (at most every
    millisecond) and sends the samples that are due, so the average rate holds even
    when a tick is late. A ``publish()`` that raises (a full KEEP_ALL history) is
    counted, not fatal. Progress and a final summary go to stdout as JSON lines.
    """

    def __init__(self, topic: str, qos: dict, rate_hz: float, payload_bytes: int, count: int,
                 wait_for_subscriber: bool = True, wait_for_node: str | None = None,
                 deadline_s: float = 30.0):
        super().__init__(PUBLISHER_NODE)
        self.rate_hz = float(rate_hz)  # samples per second
        self.count = int(count)
        self.deadline_s = float(deadline_s)  # stop trying after this long [s]
        self.publisher = self.create_publisher(ExperimentSample, topic, make_qos(qos))
        self.sample = ExperimentSample()
        self.sample.payload = array("B", bytes(payload_bytes))  # built once, reused
        self.attempted = self.published = self.errors = 0
        self.first_error = ""
        self.started_ns = 0
        self.last_report = 0.0
        self.wait_for_subscriber = wait_for_subscriber
        self.wait_for_node = wait_for_node
        self.ready_at = 0.0
        self.timer = self.create_timer(max(1.0 / self.rate_hz, 0.001), self.tick)  # period [s]
        self.timer.cancel()  # started by start()
        self.wait_timer = self.create_timer(0.01, self.check_ready)  # every 10 ms until ready

    def check_ready(self) -> None:
        if self.wait_for_subscriber and self.publisher.get_subscription_count() == 0:
            return
        if self.wait_for_node and self.wait_for_node not in {
                ns.rstrip("/") + "/" + name for name, ns in self.get_node_names_and_namespaces()}:
            return
        if not self.ready_at:
            self.ready_at = time.monotonic()
        elif time.monotonic() - self.ready_at >= MATCH_SETTLE_S:  # the other side knows us by now
            self.wait_timer.cancel()
            self.start()

    def start(self) -> None:
        self.started_ns = time.monotonic_ns()
        print(PROGRESS_TAG + json.dumps(self.report(0.0)), flush=True)
        self.timer.reset()

    def tick(self) -> None:
        elapsed_s = (time.monotonic_ns() - self.started_ns) * 1e-9
        due = min(self.count, int(elapsed_s * self.rate_hz) + 1)
        burst_end = min(due, self.attempted + 500)  # bounded work per tick
        sample, publish = self.sample, self.publisher.publish
        while self.attempted < burst_end:
            sample.seq = self.attempted
            sample.stamp_ns = time.time_ns()
            self.attempted += 1
            try:
                publish(sample)
            except RCLError as exc:  # a KEEP_ALL history is full: back-pressure
                self.errors += 1
                self.first_error = self.first_error or str(exc).strip().splitlines()[0][:200]
                break  # publish() already waited; the next tick tries again
            self.published += 1
        if self.attempted >= self.count or elapsed_s > self.deadline_s:
            self.timer.cancel()
            summary = self.report(elapsed_s)
            summary.update(first_error=self.first_error, not_attempted=self.count - self.attempted)
            print(SUMMARY_TAG + json.dumps(summary), flush=True)
        elif time.monotonic() - self.last_report > 0.1:
            self.last_report = time.monotonic()
            print(PROGRESS_TAG + json.dumps(self.report(elapsed_s)), flush=True)

    def report(self, elapsed_s: float) -> dict:
        return {"attempted": self.attempted, "published": self.published,
                "publish_errors": self.errors, "elapsed_s": round(elapsed_s, 4)}


def make_lab_publisher(topic: str, qos: dict, rate_hz: float, payload_bytes: int, count: int,
                       wait_for_subscriber: bool = True, wait_for_node: str | None = None,
                       deadline_s: float = 30.0) -> LabPublisher:
    """Child-process target (``'course_helpers.chapters.ch08b_lab.engine:make_lab_publisher'``)."""
    return LabPublisher(topic, qos, rate_hz, payload_bytes, count, wait_for_subscriber, wait_for_node,
                        deadline_s)


# ---------------------------------------------------------------------- the subscriber (kernel)
class LabSubscriber(Node):
    """Counts samples, sequence gaps, message_lost events and latency, in a cheap callback.

    ``joins_before_first_sample``: DDS numbers a writer's samples from 1, so a
    subscriber that was matched before the first one knows that a first sample
    numbered 3 means 2 were lost. A late joiner starts counting at what it gets first.
    """

    def __init__(self, topic: str, qos: dict, processing_ms: float = 0.0,
                 joins_before_first_sample: bool = True):
        super().__init__(SUBSCRIBER_NODE)
        self.delivered = 0
        self.gaps = 0  # samples missing between received publication sequence numbers
        self.last_seq = 0 if joins_before_first_sample else None
        self.first_seq = None
        self.lost_events = 0  # sum of the message_lost events' total_count_change
        self.latency_ns = array("q")  # C int64 values, no Python object per sample
        self.last_arrival = 0.0
        self.processing_s = processing_ms / 1000.0
        events = SubscriptionEventCallbacks(message_lost=self.on_message_lost)
        self.subscription = self.create_subscription(
            ExperimentSample, topic, self.on_sample, make_qos(qos), event_callbacks=events)

    def on_sample(self, msg, info) -> None:  # two parameters: rclpy passes the MessageInfo too
        self.latency_ns.append(time.time_ns() - msg.stamp_ns)
        seq = info["publication_sequence_number"]
        last = self.last_seq
        if last is None:
            self.first_seq = seq
        elif seq > last + 1:
            self.gaps += seq - last - 1
        self.last_seq = seq
        self.delivered += 1
        if self.processing_s:
            time.sleep(self.processing_s)  # stands in for the work a real callback does
        self.last_arrival = time.monotonic()

    def on_message_lost(self, info) -> None:
        self.lost_events += info.total_count_change


# ---------------------------------------------------------------------- transports
_UDP_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<!-- QoS lab (chapter 08): the publisher's participant gets one transport, UDPv4 on 127.0.0.1 -->
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>
    <transport_descriptor>
      <transport_id>qos_lab_udp_loopback</transport_id>
      <type>UDPv4</type>
      <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>
    </transport_descriptor>
  </transport_descriptors>
  <participant profile_name="qos_lab_udp_only" is_default_profile="true">
    <rtps>
      <userTransports><transport_id>qos_lab_udp_loopback</transport_id></userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>
    </rtps>
  </participant>
</profiles>
"""


def transport_env(transport: str, directory: str) -> dict:
    """Environment for the publisher child that makes its samples use ``transport``.

    'shm': the child inherits the kernel's setup; with localhost-only discovery
    rmw_fastrtps gives each participant UDP on 127.0.0.1 plus shared memory, and Fast
    DDS sends samples between processes of one machine through shared memory.
    'udp': rmw_fastrtps replaces the transports for localhost-only discovery (so
    ``FASTDDS_BUILTIN_TRANSPORTS`` alone is ignored); the child therefore uses the
    'subnet' range, 127.0.0.1 as its static peer, and a Fast DDS XML profile whose only
    transport is UDPv4 limited to 127.0.0.1. Its samples then cross the loopback
    network interface, which ``loopback_bytes()`` shows.
    """
    _check_choice("transport", transport, tuple(TRANSPORTS))
    if transport == "shm":
        return {}
    path = os.path.join(directory, "qos_lab_udp_only.xml")
    if not os.path.exists(path):
        with open(path, "w", encoding="utf-8") as handle:
            handle.write(_UDP_PROFILE)
    return {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": "127.0.0.1",
            "FASTRTPS_DEFAULT_PROFILES_FILE": path}


# ---------------------------------------------------------------------- results
@dataclass(frozen=True)
class Snapshot:
    """Where a run stands: sent by ``progress`` callbacks and kept in ``ExperimentResult.timeline``."""

    t: float  # seconds since the publisher started sending
    delivered: int  # samples the subscriber's callback got
    lost_by_sequence: int  # gaps in publication_sequence_number (plus the tail, at the end)
    lost_events: int  # DDS message_lost event count
    published: int  # samples the publisher's publish() accepted
    publish_errors: int  # publish() calls that raised
    in_flight: int = 0  # at the end of a run cut short: sent, not yet seen (not counted as lost)
    latency_p50_ms: float | None = None
    latency_p90_ms: float | None = None
    latency_p99_ms: float | None = None
    done: bool = False


@dataclass
class ExperimentResult:
    """What one run measured. ``as_row()`` gives the lab's results-table row."""

    config: ExperimentConfig
    planned: int
    published: int
    publish_errors: int
    not_attempted: int
    delivered: int
    lost_by_sequence: int
    lost_events: int
    in_flight: int  # sent, not yet seen when the run was stopped or cut short (not counted as lost)
    latency_ms: dict  # 'p50', 'p90', 'p99', 'max' (None when nothing arrived)
    send_time_s: float  # how long the publisher took to send everything
    wall_time_s: float  # the whole run, child start to clean-up
    loopback_bytes: int  # bytes through this machine's 'lo' interface during the run
    stopped: bool  # ended early by stop_event
    first_error: str = ""
    first_seq: int | None = None  # late joiner: the oldest sample's sequence number it got
    timeline: list[Snapshot] = field(default_factory=list, repr=False)

    @property
    def label(self) -> str:
        return self.config.describe()

    @property
    def delivered_ratio(self) -> float:
        """Delivered / published (0 when nothing was published)."""
        return self.delivered / self.published if self.published else 0.0

    @property
    def lost_nothing(self) -> bool:
        """True when neither way of counting saw a loss."""
        return self.lost_by_sequence == 0 and self.lost_events == 0

    def as_row(self) -> dict:
        """One row of the results table (plain values)."""
        c = self.config
        lat = self.latency_ms
        return {
            "run": c.describe(),
            "reliability": c.reliability, "durability": c.durability,
            "history": "keep_all" if c.history == "keep_all" else f"keep_last {c.depth}",
            "rate_hz": c.rate_hz, "payload": format_bytes(c.payload_bytes),
            "processing_ms": c.processing_ms, "transport": c.transport,
            "published": self.published, "delivered": self.delivered,
            "lost_seq": self.lost_by_sequence, "lost_events": self.lost_events,
            "in_flight": self.in_flight, "publish_errors": self.publish_errors,
            "p50_ms": _round(lat.get("p50")), "p99_ms": _round(lat.get("p99")),
            "loopback_mb": round(self.loopback_bytes / 1e6, 1), "stopped": self.stopped,
        }

    def summary(self) -> str:
        """One line in words."""
        if self.config.late_joiner:
            return (f"{self.label}: the late joiner got {self.delivered} of the {self.published} "
                    "samples sent before it joined")
        text = f"{self.label}: delivered {self.delivered} of {self.published} sent"
        if self.lost_nothing and not self.in_flight and self.delivered == self.published:
            text += ", nothing lost"
        else:
            text += (f", lost {self.lost_by_sequence} by sequence gaps and {self.lost_events} by "
                     "message_lost events")
        if self.in_flight:
            text += f", {self.in_flight} still in flight when the run ended"
        if self.publish_errors:
            text += f", {self.publish_errors} publish() errors"
        return text + (" (stopped)" if self.stopped else "")

    def to_dict(self) -> dict:
        out = asdict(self)
        out["config"] = asdict(self.config)
        return out


def _round(value):
    return None if value is None else round(value, 2)


def latency_percentiles(latency_ns) -> dict:
    """p50/p90/p99/max latency in ms from an array of nanoseconds (None values when empty)."""
    if not len(latency_ns):
        return {"p50": None, "p90": None, "p99": None, "max": None}
    import numpy as np

    # Copy first (a slice is one atomic C copy): a buffer view of the live array would make the
    # subscriber's append() in the executor thread fail while the view exists.
    values = np.frombuffer(latency_ns[:], dtype=np.int64) / 1e6
    p50, p90, p99 = np.percentile(values, [50, 90, 99])
    return {"p50": float(p50), "p90": float(p90), "p99": float(p99), "max": float(values.max())}


# ---------------------------------------------------------------------- the engine
_run_lock = threading.Lock()
_run_counter = 0


def loopback_bytes() -> int:
    """Bytes received so far on this machine's loopback interface (from /proc/net/dev; 0 if unknown)."""
    try:
        with open("/proc/net/dev", encoding="ascii") as handle:
            for line in handle:
                name, _, data = line.partition(":")
                if name.strip() == "lo":
                    return int(data.split()[0])
    except (OSError, ValueError, IndexError):
        pass
    return 0


class _ChildReports:
    """Reads the publisher child's JSON report lines as they are written (only the new part)."""

    def __init__(self, child):
        self.handle = open(child.log_path, encoding="utf-8", errors="replace")
        self.pending = ""
        self.progress: dict | None = None
        self.summary: dict | None = None

    def poll(self) -> tuple[dict | None, dict | None]:
        """The latest progress report and the final summary (None when not written yet)."""
        lines = (self.pending + self.handle.read()).split("\n")
        self.pending = lines.pop()  # the last piece may be half written
        for line in lines:
            for tag in (PROGRESS_TAG, SUMMARY_TAG):
                if line.startswith(tag):
                    try:
                        report = json.loads(line[len(tag):])
                    except ValueError:
                        continue
                    if tag == SUMMARY_TAG:
                        self.summary = report
                    else:
                        self.progress = report
        return self.progress, self.summary

    def close(self) -> None:
        self.handle.close()


def run_experiment(config: ExperimentConfig, progress=None, stop_event: threading.Event | None = None,
                   progress_period_s: float = 0.1) -> ExperimentResult:
    """Run one real experiment and return what it measured.

    ``progress(snapshot)`` is called about every ``progress_period_s`` seconds (in
    this thread) with a :class:`Snapshot`. Setting ``stop_event`` ends the run: the
    publisher child is stopped within a second and the result has ``stopped=True``.
    Only one experiment runs at a time per kernel.
    """
    if not isinstance(config, ExperimentConfig):
        raise CourseError(f"run_experiment() takes an ExperimentConfig, got {type(config).__name__}")
    if progress_period_s <= 0:
        raise CourseError(f"progress_period_s must be > 0, got {progress_period_s!r}")
    if not _run_lock.acquire(blocking=False):
        raise CourseError("another QoS lab experiment is running in this kernel; stop it first "
                          "(the panel's Stop button, or set its stop_event).")
    try:
        return _run(config, progress, stop_event or threading.Event(), progress_period_s)
    finally:
        _run_lock.release()


def _run(config, progress, stop_event, period_s):
    from course_helpers.core.runtime import get_runtime

    global _run_counter
    _run_counter += 1
    rt = get_runtime()
    topic = f"/qos_lab/run_{os.getpid()}_{_run_counter}"  # a fresh topic: nothing left from old runs
    qos = config.qos_dict()
    wall_start = time.monotonic()
    lo_start = loopback_bytes()
    run = _RunState()
    child = reports = None
    try:
        if not config.late_joiner:  # subscribe first, so the publisher can wait until it is matched
            run.sub = rt.add(LabSubscriber, topic, qos, config.processing_ms, True, console=False)
        child = rt.spawn(
            CHILD_LABEL, "course_helpers.chapters.ch08b_lab.engine:make_lab_publisher",
            params={"topic": topic, "qos": qos, "rate_hz": config.rate_hz,
                    "payload_bytes": config.payload_bytes, "count": config.count,
                    "wait_for_subscriber": not config.late_joiner,
                    "wait_for_node": rt.graph.get_fully_qualified_name() if config.late_joiner else None,
                    "deadline_s": _send_deadline_s(config)},
            env=transport_env(config.transport, rt.log_dir))
        reports = _ChildReports(child)
        connect_deadline = time.monotonic() + _MATCH_TIMEOUT_S
        while True:
            if stop_event.wait(period_s if run.send_start is not None else 0.02):
                run.stopped = True
                break
            now = time.monotonic()
            run.progress_line, run.summary = reports.poll()
            if run.send_start is None:  # the child starts, then waits for the subscriber
                if run.progress_line is None:
                    _check_child_starting(child, now, connect_deadline, config)
                    continue
                run.send_start = now
            if run.summary is not None and run.summary_at is None:
                run.summary_at = now
                if config.late_joiner:  # everything is sent: now the subscriber joins
                    run.sub = rt.add(LabSubscriber, topic, qos, config.processing_ms, False,
                                     console=False)
            snap = _snapshot(run.sub, run.progress_line, run.summary, now - run.send_start)
            run.timeline.append(snap)
            if progress is not None:
                progress(snap)
            if run.summary_at is None:
                if not child.alive:
                    raise CourseError("the lab's publisher process ended before it finished. "
                                      f"Its output:\n{child.log()[-2000:]}")
                continue
            if _finished(run, now, config):
                break
            if not config.late_joiner and _drain_hopeless(run, now, config):
                run.cut_short = True  # samples were still coming: report them as in flight
                break
    finally:
        if child is not None:
            child.stop(grace_s=0.5)
            rt.stop_child(CHILD_LABEL)
        if run.sub is not None:
            rt.remove(run.sub)
        if reports is not None:
            if run.summary is None:  # stopped early: what the child had reported until then
                run.progress_line, run.summary = reports.poll()
            reports.close()
    return _result(config, run, time.monotonic() - wall_start, loopback_bytes() - lo_start)


@dataclass
class _RunState:
    sub: object = None
    progress_line: dict | None = None
    summary: dict | None = None
    send_start: float | None = None  # when the child reported it started sending (our clock)
    summary_at: float | None = None  # when we saw the child's final summary
    matched_at: float | None = None  # late joiner: when its subscription matched the writer
    stopped: bool = False
    cut_short: bool = False
    timeline: list = field(default_factory=list)


def _send_deadline_s(config) -> float:
    """How long the publisher may take to send everything (back-pressure slows it down)."""
    return config.duration_s * 1.25 + 1.0


def _check_child_starting(child, now, deadline, config) -> None:
    if not child.alive:
        raise CourseError(f"the lab's publisher process exited with code {child.returncode}. "
                          f"Its output:\n{child.log()[-2000:]}")
    if now > deadline:
        raise CourseError(
            f"the publisher and subscriber did not connect within {_MATCH_TIMEOUT_S:g} s (transport "
            f"{config.transport!r}). Publisher output:\n{child.log()[-2000:]}")


def _finished(run, now, config) -> bool:
    """True when nothing more is to come."""
    sub = run.sub
    if config.late_joiner:
        if run.matched_at is None:
            if sub.subscription.get_publisher_count() == 0:  # not matched with the writer yet
                if now - run.summary_at > _MATCH_TIMEOUT_S:
                    raise CourseError(f"the late joiner did not match the publisher within "
                                      f"{_MATCH_TIMEOUT_S:g} s")
                return False
            run.matched_at = now
        if sub.delivered == 0:  # nothing yet: give a repair a chance (one heartbeat period)
            return now - run.matched_at >= _RELIABLE_IDLE_END_S
        return now - max(run.matched_at, sub.last_arrival) >= _LATE_JOIN_LISTEN_S
    if run.summary["published"] == 0:
        return True
    if sub.last_seq is not None and sub.last_seq >= run.summary["published"]:
        return True  # the last sample that was sent has arrived
    # Nothing arrived for a while. A reliable reader learns about missing samples from the writer's
    # heartbeats (every 3 s by default in Fast DDS), so it gets a longer wait.
    idle = _IDLE_END_S if config.reliability == "best_effort" else _RELIABLE_IDLE_END_S
    return now - max(run.summary_at, sub.last_arrival) > idle


def _drain_hopeless(run, now, config) -> bool:
    """After the publisher is done: stop waiting for queued samples after a while."""
    waited = now - run.summary_at
    limit = _DRAIN_LIMIT_S * (3 if config.reliability == "reliable" else 1)
    if waited > limit:
        return True
    if waited < 0.5 or len(run.timeline) < 2:
        return False
    # A subscriber that is busy but slow (KEEP_ALL back-pressure): would the rest take far too long?
    recent = [s for s in run.timeline if s.t >= run.timeline[-1].t - 0.5]
    rate = (recent[-1].delivered - recent[0].delivered) / max(recent[-1].t - recent[0].t, 1e-3)
    remaining = run.summary["published"] - (run.sub.last_seq or 0)
    return rate > 0 and remaining > rate * (limit - waited) * 2


def _snapshot(sub, progress_line, summary, t) -> Snapshot:
    report = summary or progress_line or {}
    published = report.get("published", 0)
    if sub is None:
        delivered = gaps = events = 0
        lat = latency_percentiles(array("q"))
    else:
        delivered, gaps, events = sub.delivered, sub.gaps, sub.lost_events
        lat = latency_percentiles(sub.latency_ns)
        if summary is None and sub.last_seq:  # the child reports every 0.1 s; a sample that
            published = max(published, sub.last_seq)  # arrived with number N proves N were sent
    return Snapshot(t=round(t, 4), delivered=delivered, lost_by_sequence=gaps, lost_events=events,
                    published=published, publish_errors=report.get("publish_errors", 0),
                    latency_p50_ms=lat["p50"], latency_p90_ms=lat["p90"], latency_p99_ms=lat["p99"])


def _result(config, run, wall_s, lo_bytes) -> ExperimentResult:
    report = run.summary or run.progress_line or {}
    sub = run.sub
    published = int(report.get("published", 0))
    gaps = in_flight = 0
    if sub is not None:
        gaps = sub.gaps
        tail = max(0, published - (sub.last_seq or 0)) if not config.late_joiner else 0
        if run.summary is None or run.stopped or run.cut_short:
            in_flight = tail  # the run ended while samples could still arrive: not counted as lost
        else:
            gaps += tail  # nothing more arrived: the samples after the last one that did are lost
    lat = latency_percentiles(sub.latency_ns if sub is not None else array("q"))
    events = sub.lost_events if sub is not None else 0
    delivered = sub.delivered if sub is not None else 0
    errors = int(report.get("publish_errors", 0))
    t_end = time.monotonic() - run.send_start if run.send_start is not None else 0.0
    final = Snapshot(t=round(t_end, 4), delivered=delivered, lost_by_sequence=gaps, lost_events=events,
                     published=published, publish_errors=errors, in_flight=in_flight,
                     latency_p50_ms=lat["p50"], latency_p90_ms=lat["p90"], latency_p99_ms=lat["p99"],
                     done=True)
    return ExperimentResult(
        config=config, planned=config.count, published=published, publish_errors=errors,
        not_attempted=config.count - int(report.get("attempted", 0)), delivered=delivered,
        lost_by_sequence=gaps, lost_events=events, in_flight=in_flight, latency_ms=lat,
        send_time_s=float(report.get("elapsed_s", 0.0)), wall_time_s=wall_s, loopback_bytes=lo_bytes,
        stopped=run.stopped, first_error=report.get("first_error", ""),
        first_seq=sub.first_seq if sub is not None else None, timeline=[*run.timeline, final])


# ---------------------------------------------------------------------- presets
PRESETS: dict[str, dict] = {
    "best-effort vs reliable under load": {
        "what": "300 samples of 1 MiB at 400 Hz, more than this machine moves in time; KEEP_LAST 300 so "
                "the writer holds the whole burst. Best-effort drops what does not fit; reliable resends "
                "what the reader missed, later but complete.",
        "configs": [
            ExperimentConfig(reliability="best_effort", depth=300, rate_hz=400, payload_bytes=2**20,
                             duration_s=0.75, label="best-effort, 1 MiB @ 400 Hz"),
            ExperimentConfig(reliability="reliable", depth=300, rate_hz=400, payload_bytes=2**20,
                             duration_s=0.75, label="reliable, 1 MiB @ 400 Hz"),
        ],
    },
    "depth 1 vs 100, slow subscriber": {
        "what": "200 Hz, the subscriber needs 10 ms per sample: with depth 1 the reader keeps only "
                "the newest sample and the others are overwritten; depth 100 queues them.",
        "configs": [
            ExperimentConfig(reliability="reliable", depth=1, rate_hz=200, payload_bytes=1024,
                             processing_ms=10, duration_s=1.0, label="depth 1, 10 ms/sample"),
            ExperimentConfig(reliability="reliable", depth=100, rate_hz=200, payload_bytes=1024,
                             processing_ms=10, duration_s=1.0, label="depth 100, 10 ms/sample"),
        ],
    },
    "late joiner: volatile vs transient_local": {
        "what": "The publisher sends 20 samples, then the subscriber joins: VOLATILE gets none of "
                "them, TRANSIENT_LOCAL gets the last `depth` the writer kept.",
        "configs": [
            ExperimentConfig(durability="volatile", depth=10, rate_hz=100, duration_s=0.2,
                             late_joiner=True, label="late joiner, volatile"),
            ExperimentConfig(durability="transient_local", depth=10, rate_hz=100, duration_s=0.2,
                             late_joiner=True, label="late joiner, transient_local"),
        ],
    },
    "KEEP_ALL back-pressure": {
        "what": "KEEP_ALL reliable, a slow subscriber: the writer may not drop anything, its history "
                "fills, and publish() fails (RCLError), counted per run.",
        "configs": [
            ExperimentConfig(reliability="reliable", history="keep_all", depth=None, rate_hz=5000,
                             payload_bytes=16, processing_ms=100, duration_s=4.0,
                             label="keep_all, 5000 Hz, 100 ms/sample"),
        ],
    },
}


def preset(name: str) -> list[ExperimentConfig]:
    """The configurations of a named preset (see ``PRESETS``)."""
    try:
        return list(PRESETS[name]["configs"])
    except KeyError:
        raise CourseError(f"unknown preset {name!r}; presets: {', '.join(sorted(PRESETS))}") from None
