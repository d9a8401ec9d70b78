"""Checkers of chapter 03 (topics): each runs the student's code against real nodes.

* :func:`check_tilt_warning` - a node class that warns on ``/safety/tilt_warning`` when the IMU
  on ``/imu`` tilts more than 15°; the checker publishes scripted attitudes.
* :func:`check_cmd_vel_logger` - a node class ``Logger(csv_path)`` that writes ``/cmd_vel`` to a
  CSV file; the checker publishes known Twists and reads the file back.
* :func:`check_throughput` - ``expected_load`` (computed) and ``measure_load`` (measured) for
  10 IMUs at 100 Hz, compared with what the sensors really sent.
"""

from __future__ import annotations

import csv
import math
import os
import shutil
import tempfile
import time

from geometry_msgs.msg import Twist
from sensor_msgs.msg import Imu
from std_msgs.msg import String

from course_helpers.chapters.ch03_topics import (
    ArrayListener,
    imu_message,
    make_sensor_array,
    message_size,
    sensor_topics,
    sent_rate,
)
from course_helpers.checks import (
    CheckReport,
    _describe,
    callback_errors_criterion,
    judge_timed_scenario,
    student_on_clock,
)
from course_helpers.core.names import full_name

TILT_THRESHOLD_DEG = 15.0
# (roll, pitch, yaw) in degrees, and whether the attitude is tilted by more than 15°
TILT_CASES = [
    ((0, 0, 0), False),
    ((10, 0, 0), False),
    ((0, 10, 0), False),
    ((0, -14, 0), False),
    ((0, 0, 90), False),
    ((20, 0, 0), True),
    ((30, 0, 0), True),
    ((0, 20, 0), True),
    ((0, -30, 0), True),
    ((12, 12, 0), True),
]
CSV_COLUMNS = ["time_s", "linear_x", "linear_y", "linear_z", "angular_x", "angular_y", "angular_z"]
SENSOR_COUNT, SENSOR_RATE_HZ = 10, 100.0
CASE_STEP_S = 0.1  # the checker's clock moves this much after each scripted attitude
CSV_PERIOD_S = 0.1  # one Twist every 0.1 s of the checker's clock
STARTS_HINT = ("Run the class cell first; its __init__ must call super().__init__(name) and take exactly "
               "the arguments the exercise gives.")


def _tilt_of(roll: float, pitch: float) -> float:
    """The tilt (degrees) of a roll-then-pitch attitude: acos(cos(roll)·cos(pitch))."""
    return math.degrees(math.acos(math.cos(math.radians(roll)) * math.cos(math.radians(pitch))))


def _node_name(node) -> str:
    return node.get_fully_qualified_name()


def _endpoint_types(graph, topic: str, node, publishers: bool) -> list[str]:
    """The types of ``node``'s publishers (or subscriptions) on ``topic``, as ``graph`` (a node) sees
    them; the nodes of this process are listed as soon as they exist."""
    infos = (graph.get_publishers_info_by_topic(topic) if publishers
             else graph.get_subscriptions_info_by_topic(topic))
    name, namespace = node.get_name(), node.get_namespace()
    return [i.topic_type for i in infos if i.node_name == name and i.node_namespace == namespace]


def _types_detail(types: list[str], wanted: str) -> str:
    """Empty when exactly the wanted type was found, else what was found."""
    if len(types) == 1 and types[0].endswith("/" + wanted):
        return ""
    return f"found: {', '.join(types)}" if types else "none found in the graph"


def _other_publishers(graph, topic: str, allowed: set[str]) -> list[str]:
    """Full names of the nodes publishing on ``topic`` other than those in ``allowed``."""
    names = {full_name(i.node_namespace, i.node_name) for i in graph.get_publishers_info_by_topic(topic)}
    return sorted(names - allowed)


def _no_intruders(report: CheckReport, graph, topics: list[str], allowed: set[str]) -> bool:
    """A criterion: nobody but the checker and the student's node publishes on ``topics``."""
    others = sorted({n for t in topics for n in _other_publishers(graph, t, allowed)})
    return report.add(f"no other node publishes on {' or '.join(topics)}", not others,
                      f"also published by {', '.join(others)}" if others else "",
                      hint="Their messages would mix with the checker's. Stop them first, e.g. "
                           "rt.remove('/imu_driver') for a node of this kernel or "
                           "rt.stop_child(label) for a child process, then check again.")


# ---------------------------------------------------------------------- exercise 1
def check_tilt_warning(node_class, rt=None) -> CheckReport:
    """Check a tilt-warning node class: warnings on /safety/tilt_warning exactly when tilt > 15°.

    ``node_class()`` builds the node (no arguments); ``rt`` is the course runtime (default: this
    process's). The node runs on the checker's clock (:func:`~course_helpers.checks.student_on_clock`):
    after each scripted attitude, every warning the node was going to publish has arrived, so "no
    warning" is exact. Returns a :class:`CheckReport`, one criterion per scripted attitude.
    """
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport("Exercise 1: IMU tilt warning")
    with student_on_clock(report, rt, node_class, "tilt_checker", created="the node starts",
                          hint=STARTS_HINT) as (node, probe, clock):
        if node is None:
            return report
        report.add("the node starts", True, _node_name(node))
        sub_types = _endpoint_types(probe, "/imu", node, publishers=False)
        pub_types = _endpoint_types(probe, "/safety/tilt_warning", node, publishers=True)
        subscribes = report.add("subscribes to /imu with type sensor_msgs/msg/Imu",
                                sub_types == ["sensor_msgs/msg/Imu"], _types_detail(sub_types, "Imu"),
                                hint="TODO 2: the exercise names the topic and its message type; "
                                     "section 1's monitor shows how a node subscribes.")
        publishes = report.add("publishes on /safety/tilt_warning with type std_msgs/msg/String",
                               pub_types == ["std_msgs/msg/String"], _types_detail(pub_types, "String"),
                               hint="TODO 1: the exercise names the topic and its message type; "
                                    "section 1's thermometer shows how a node publishes.")
        if not (subscribes and publishes):
            report.add("scripted attitudes", False, "not run: the node must subscribe and publish first",
                       hint="Fix the two criteria above, then check again.")
            return report
        # One process cannot use a topic name with two types, so the probe's ends come after the type check.
        warnings: list[str] = []
        imu_pub = probe.create_publisher(Imu, "/imu", 10)
        probe.create_subscription(String, "/safety/tilt_warning", lambda m: warnings.append(m.data), 10)
        clock.wait_matched()
        if not _no_intruders(report, probe, ["/imu", "/safety/tilt_warning"],
                             {_node_name(probe), _node_name(node)}):
            return report
        for (roll, pitch, yaw), tilted in TILT_CASES:
            _run_tilt_case(report, clock, imu_pub, warnings, roll, pitch, yaw, tilted)
        callback_errors_criterion(report, clock.errors)
    return report


def _run_tilt_case(report, clock, publisher, warnings, roll, pitch, yaw, tilted) -> None:
    warnings.clear()
    msg = imu_message(roll, pitch, yaw)
    msg.header.stamp = clock.node.get_clock().now().to_msg()
    publisher.publish(msg)
    clock.step(CASE_STEP_S)  # the node's callbacks have run: whatever it warns has arrived
    tilt = _tilt_of(roll, pitch)
    label = f"roll {roll:>3}°, pitch {pitch:>3}°, yaw {yaw:>2}° (tilt {tilt:4.1f}°)"
    if tilted:
        hint = ("Reread how the exercise defines tilt from the orientation quaternion: roll and pitch "
                "both count, together.")
        report.add(f"{label}: warning", bool(warnings), "" if warnings else "no warning", hint)
    else:
        hint = ("Reread the exercise: which attitudes count as tilted, and which rotation does not "
                "change the tilt at all?")
        report.add(f"{label}: no warning", not warnings, f"got {warnings[0]!r}" if warnings else "", hint)


# ---------------------------------------------------------------------- exercise 2
CSV_TWISTS = [  # (linear x, y, z, angular x, y, z): every column different, so swaps show
    (0.5, 0.0, 0.0, 0.0, 0.0, 0.1),
    (0.25, -0.125, 0.0, 0.0, 0.0, -0.5),
    (0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    (-0.3, 0.2, 0.05, 0.01, -0.02, 1.5),
    (1.0, 0.5, -0.25, 0.125, 0.0625, -1.25),
]


def check_cmd_vel_logger(node_class, rt=None) -> CheckReport:
    """Check a /cmd_vel CSV logger: header, one flushed row per Twist, values in the right columns, and
    the receive time on the node's clock.

    ``node_class(csv_path)`` builds the node; ``rt`` is the course runtime (default: this process's).
    The node runs on the checker's clock, so each Twist's receive time is known exactly: the checker
    sends one every ``CSV_PERIOD_S`` of its clock. Returns a :class:`CheckReport`.
    """
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport("Exercise 2: CSV logger of /cmd_vel")
    folder = tempfile.mkdtemp(prefix="cmd-vel-check-")
    path = os.path.join(folder, "cmd_vel.csv")
    try:
        with student_on_clock(report, rt, _Logging(node_class, path), "cmd_vel_checker",
                              created="the node starts", hint=STARTS_HINT) as (node, probe, clock):
            if node is None:
                return report
            report.add("the node starts", True, f"{_node_name(node)} writing {os.path.basename(path)}")
            sub_types = _endpoint_types(probe, "/cmd_vel", node, publishers=False)
            if not report.add("subscribes to /cmd_vel with type geometry_msgs/msg/Twist",
                              sub_types == ["geometry_msgs/msg/Twist"], _types_detail(sub_types, "Twist"),
                              hint="TODO 2: the exercise names the topic and its message type; section 1 "
                                   "shows how a node subscribes."):
                return report
            publisher = probe.create_publisher(Twist, "/cmd_vel", 10)
            clock.wait_matched()
            if not _no_intruders(report, probe, ["/cmd_vel"], {_node_name(probe)}):
                return report
            sent_at = []
            for values in CSV_TWISTS:
                clock.step(CSV_PERIOD_S)
                publisher.publish(_twist(*values))
                sent_at.append(clock.now_s)
                clock.settle()
            lines = _read_lines(path)  # while the node runs: the rows must be on disk already
            expected_lines = 1 + len(CSV_TWISTS)
            report.add("rows are on disk while the node runs", len(lines) >= expected_lines,
                       f"{len(lines)} line(s) in the file after 5 messages",
                       hint="A file object keeps written rows in a buffer; the exercise's third bullet "
                            "says what to do after each row (TODO 3).")
            _check_csv_content(report, lines, sent_at)
            callback_errors_criterion(report, clock.errors)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return report


class _Logging:
    """``node_class(path)`` as a factory of no arguments (what student_on_clock builds)."""

    def __init__(self, node_class, path: str):
        self.node_class, self.path = node_class, path
        self.__name__ = getattr(node_class, "__name__", "the logger")

    def __call__(self, **kwargs):
        return self.node_class(self.path, **kwargs)


def _twist(lx, ly, lz, ax, ay, az) -> Twist:
    msg = Twist()
    msg.linear.x, msg.linear.y, msg.linear.z = lx, ly, lz
    msg.angular.x, msg.angular.y, msg.angular.z = ax, ay, az
    return msg


def _read_lines(path: str) -> list[list[str]]:
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            return [row for row in csv.reader(handle) if row]
    except OSError:
        return []


def _check_csv_content(report: CheckReport, lines: list[list[str]], sent_at: list[float]) -> None:
    header = lines[0] if lines else []
    header_ok = report.add("header row is " + ",".join(CSV_COLUMNS), header == CSV_COLUMNS,
                           "" if header == CSV_COLUMNS else f"got {','.join(header) or 'nothing'}",
                           hint="TODO 1: the header comes before any message arrives; compare it "
                                "with the exercise's header, character for character.")
    if lines and not header_ok and _is_number_row(lines[0]):
        rows = lines  # no header at all: every line is data
    else:
        rows = lines[1:]
    report.add(f"one row per message ({len(CSV_TWISTS)})", len(rows) == len(CSV_TWISTS),
               f"{len(rows)} data row(s)", hint="What does one /cmd_vel message become in the file? "
                                                  "Look at what each call of on_twist writes.")
    problems = []
    for index, (row, values) in enumerate(zip(rows, CSV_TWISTS, strict=False)):
        if len(row) != len(CSV_COLUMNS):
            problems.append(f"row {index + 1} has {len(row)} columns, expected {len(CSV_COLUMNS)}")
            continue
        for column, want, got in zip(CSV_COLUMNS[1:], values, row[1:], strict=True):
            if not _close(got, want):
                problems.append(f"row {index + 1} {column}: expected {want}, got {got}")
                break
    report.add("velocities in the right columns, in message order", rows and not problems,
               problems[0] if problems else "",
               hint="Compare the order of your values with the exercise's header row; each cell "
                    "is a plain number.")
    stamps = []
    for row in rows:
        try:
            stamps.append(float(row[0]))
        except (ValueError, IndexError):
            stamps = []
            break
    exact = len(stamps) == len(sent_at) and all(math.isclose(s, t, abs_tol=1e-3)
                                                for s, t in zip(stamps, sent_at, strict=True))
    report.add("time_s is the receive time on the node's clock, in seconds", exact,
               "" if exact else (f"time_s {', '.join(f'{s:.3f}' for s in stamps[:3])}..., the node's clock "
                                 f"read {', '.join(f'{t:.3f}' for t in sent_at[:3])}..." if stamps
                                 else "time_s missing or not a number"),
               hint="The exercise's second bullet names the clock to read (the node's own, "
                    "self.get_clock().now(): the checker runs your node on a clock it owns) and the unit.")


def _is_number_row(row: list[str]) -> bool:
    try:
        [float(v) for v in row]
    except ValueError:
        return False
    return True


def _pair_close(got, want: tuple[float, float]) -> bool:
    if not (isinstance(got, (tuple, list)) and len(got) == 2):
        return False
    try:
        return all(math.isclose(float(g), w, rel_tol=1e-9, abs_tol=1e-9)
                   for g, w in zip(got, want, strict=True))
    except (TypeError, ValueError):
        return False


def _close(text: str, want: float) -> bool:
    try:
        return math.isclose(float(text), want, rel_tol=1e-9, abs_tol=1e-9)
    except ValueError:
        return False


# ---------------------------------------------------------------------- exercise 3
LOAD_CASES = [(10, 100.0, 324), (3, 30.0, 921_600), (1, 1.0, 0)]


class ArrivalWitness(ArrayListener):
    """The checker's own subscriptions beside the student's: the arrival time of every message.

    A busy kernel takes fewer messages off the wire than the sensors send; what arrived here in the
    student's window, not what was sent, is what a correct ``measure_load`` reports.
    """

    def __init__(self, topics: list[str]):
        super().__init__(topics, name="load_witness")
        self.arrivals: list[float] = []  # time.monotonic() of each message [s]

    def on_message(self, raw: bytes) -> None:
        super().on_message(raw)
        self.arrivals.append(time.monotonic())

    def rate(self, start: float, end: float) -> float:
        """Messages per second that arrived between two ``time.monotonic()`` instants."""
        return sum(start <= t <= end for t in self.arrivals) / (end - start)


def check_throughput(expected_load, measure_load, rt=None, duration_s: float = 2.0) -> CheckReport:
    """Check ``expected_load(n, rate_hz, bytes)`` and ``measure_load(node, topics, duration_s)``.

    Args:
        expected_load: returns (messages/s, bytes/s) computed for ``n`` sensors at ``rate_hz``.
        measure_load: subscribes with ``node`` to ``topics`` and returns the measured (messages/s,
            bytes/s).
        rt: the course runtime (default: this process's).
        duration_s: passed to ``measure_load``.

    Returns:
        A :class:`CheckReport`. The measured part starts 10 IMU publishers at 100 Hz in a child
        process and compares the measurement with what the checker's own subscriptions received
        in this kernel during the same seconds, and with the rate the sensors report they sent.
    """
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport("Exercise 3: throughput of 10 sensors at 100 Hz")
    for n, rate, size in LOAD_CASES:
        want = (n * rate, n * rate * size)
        name = f"expected_load({n}, {rate:g}, {size}) = ({want[0]:g} msg/s, {want[1]:,.0f} B/s)"
        failures_before = len(report.criteria)
        got = report.run(name, lambda n=n, r=rate, s=size: expected_load(n, r, s),
                         hint="Return a (messages per second, bytes per second) tuple.")
        if len(report.criteria) > failures_before:
            continue  # it raised; report.run recorded the error
        ok = _pair_close(got, want)
        report.add(name, ok, "" if ok else f"got {got!r}",
                   hint="Section 6 says what the load of a topic is made of.")
    message_bytes = message_size(imu_message(frame_id="imu_0"))
    array = rt.spawn("sensor_array", make_sensor_array, {"count": SENSOR_COUNT, "rate_hz": SENSOR_RATE_HZ},
                     wait_for="/sensor_array")
    topics = sensor_topics(SENSOR_COUNT)
    witness = rt.add(ArrivalWitness, topics, console=False)
    try:
        rt.wait_until(lambda: all(rt.graph.count_publishers(t) for t in topics), 10, "10 sensor topics")
        judge_timed_scenario(report, "measure_load's figures match what arrived",
                             lambda: _measure_scenario(rt, measure_load, topics, (array, witness),
                                                       duration_s, message_bytes))
    finally:
        rt.remove(witness)
        rt.remove("load_meter")
        rt.stop_child("sensor_array")
    return report


MEASURE = "measure_load(node, topics, duration_s) returns (messages/s, bytes/s)"
MEASURE_HINT = ("Subscribe to every topic, count messages and bytes for duration_s seconds, return "
                "(messages/s, bytes/s).")


def _measure_scenario(rt, measure_load, topics, sources, duration_s: float, message_bytes: int) -> list:
    """One measurement by the student's function on a fresh node, judged against the witness.

    Whether it runs and what it returns are the code's (structural); how many messages arrived in a
    window is the machine's (timed). The ratio of bytes to messages does not depend on how many came."""
    array, witness = sources
    meter = rt.node("load_meter", console=False)
    started = time.monotonic()
    try:
        measured = measure_load(meter, topics, duration_s)
    except Exception as exc:  # the student's code raised: a failed criterion, not a crash
        return [(MEASURE, False, _describe(exc), MEASURE_HINT, True)]
    ended = time.monotonic()
    if not (isinstance(measured, (tuple, list)) and len(measured) == 2):
        return [(MEASURE, False, f"got {measured!r}", "Return a tuple of two numbers.", True)]
    msgs_per_s, bytes_per_s = (float(v) for v in measured)
    arrived = witness.rate(max(started, ended - duration_s), ended)  # the student's window ends at the return
    matches = math.isclose(msgs_per_s, arrived, rel_tol=0.15)
    per_message = bytes_per_s / msgs_per_s if msgs_per_s > 0 else 0.0
    sized = math.isclose(per_message, message_bytes, rel_tol=0.05)
    computed = SENSOR_COUNT * SENSOR_RATE_HZ
    agree = math.isclose(msgs_per_s, computed, rel_tol=0.25)
    return [
        (MEASURE, True, "", MEASURE_HINT),
        ("measured messages/s matches what arrived in this kernel meanwhile (within 15%)", matches,
         "" if matches else f"measured {msgs_per_s:.0f} msg/s; the checker's own subscriptions received "
         f"{arrived:.0f} msg/s in the same seconds",
         "Are all ten topics counted, over the seconds you really counted for? The exercise's tips say "
         "when to start counting."),
        (f"measured bytes/s ÷ messages/s is the message size ({message_bytes} B, within 5%)", sized,
         "" if sized else f"{per_message:.0f} B per message",
         "Reread the exercise's tip about raw=True: what does the callback receive, and what do you "
         "add up?", msgs_per_s > 0),
        (f"computed ({computed:g} msg/s) and measured agree within 25%", agree,
         "" if agree else f"measured {msgs_per_s:.0f} msg/s; the sensors sent "
         f"{sent_rate(array, started, ended):.0f} msg/s meanwhile",
         "Compare your measurement with your computed value: which topics did you count?"),
    ]
