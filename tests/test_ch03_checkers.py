"""Chapter 03's checkers: each accepts the reference solution, and every criterion fails on a wrong one.

Real nodes over real Fast DDS. Each wrong solution below is a mistake a student makes; the table
next to it names the criteria it must fail. The test that runs the reference solution also checks
that the tables cover every criterion the checker reports.
"""

from __future__ import annotations

import csv
import math
import time

import pytest
from sensor_msgs.msg import Imu
from std_msgs.msg import Bool, String

from course_helpers.chapters.ch03_topics import CmdVelPublisher, ImuPublisher
from course_helpers.checks.ch03_topics import check_cmd_vel_logger, check_throughput, check_tilt_warning
from course_helpers.solutions import ch03_topics as solution

from .criteria_registry import assert_reference_criteria


def _failed(report) -> set[str]:
    return {c.name for c in report.criteria if not c.passed}


def _covered(table) -> set[str]:
    return set().union(*(param.values[1] for param in table))


# ---------------------------------------------------------------------- exercise 1: tilt warning
class TiltNeedsAThreshold(solution.TiltMonitor):
    """Wrong: the constructor takes an argument the checker does not give."""

    def __init__(self, threshold_deg):
        super().__init__(threshold_deg)


class TiltOnImuData(solution.TiltMonitor):
    """Wrong: listens to /imu/data, the conventional name of another driver, not /imu."""

    def __init__(self):
        super().__init__()
        self.destroy_subscription(self.imu_sub)
        self.imu_sub = self.create_subscription(Imu, "/imu/data", self.on_imu, 10)


class TiltOnBoolTopic(solution.TiltMonitor):
    """Wrong: publishes the warning as a Bool."""

    def __init__(self):
        super().__init__()
        self.destroy_publisher(self.warning_pub)
        self.warning_pub = self.create_publisher(Bool, "/safety/tilt_warning", 10)


class TiltAlwaysWarns(solution.TiltMonitor):
    """Wrong: warns on every message, tilted or not."""

    def on_imu(self, msg):
        self.warning_pub.publish(String(data="tilt"))


def _roll_pitch_deg(q) -> tuple[float, float]:
    """The roll and pitch (degrees) of an orientation quaternion."""
    roll = math.atan2(2 * (q.w * q.x + q.y * q.z), 1 - 2 * (q.x * q.x + q.y * q.y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (q.w * q.y - q.z * q.x))))
    return math.degrees(roll), math.degrees(pitch)


class TiltFromRollOnly(solution.TiltMonitor):
    """Wrong: takes the roll angle for the tilt."""

    def on_imu(self, msg):
        if abs(_roll_pitch_deg(msg.orientation)[0]) > 15.0:
            self.warning_pub.publish(String(data="rolled over 15 deg"))


class TiltFromPitchOnly(solution.TiltMonitor):
    """Wrong: takes the pitch angle for the tilt."""

    def on_imu(self, msg):
        if abs(_roll_pitch_deg(msg.orientation)[1]) > 15.0:
            self.warning_pub.publish(String(data="pitched over 15 deg"))


class TiltThatRaises(solution.TiltMonitor):
    """Wrong: reads a field an Imu message does not have; the callback raises."""

    def on_imu(self, msg):
        if msg.orientation.roll > 15.0:
            self.warning_pub.publish(String(data="tilted"))


NO_WARNING_CASES = {"roll   0°, pitch   0°, yaw  0° (tilt  0.0°): no warning",
                    "roll  10°, pitch   0°, yaw  0° (tilt 10.0°): no warning",
                    "roll   0°, pitch  10°, yaw  0° (tilt 10.0°): no warning",
                    "roll   0°, pitch -14°, yaw  0° (tilt 14.0°): no warning",
                    "roll   0°, pitch   0°, yaw 90° (tilt  0.0°): no warning"}
ROLL_20, ROLL_30 = ("roll  20°, pitch   0°, yaw  0° (tilt 20.0°): warning",
                    "roll  30°, pitch   0°, yaw  0° (tilt 30.0°): warning")
PITCH_20, PITCH_30 = ("roll   0°, pitch  20°, yaw  0° (tilt 20.0°): warning",
                      "roll   0°, pitch -30°, yaw  0° (tilt 30.0°): warning")
BOTH_12 = "roll  12°, pitch  12°, yaw  0° (tilt 16.9°): warning"
TILT_WRONG = [
    pytest.param(TiltNeedsAThreshold, {"the node starts"}, id="constructor-argument"),
    pytest.param(TiltOnImuData, {"subscribes to /imu with type sensor_msgs/msg/Imu", "scripted attitudes"},
                 id="wrong-topic"),
    pytest.param(TiltOnBoolTopic, {"publishes on /safety/tilt_warning with type std_msgs/msg/String"},
                 id="bool-warning"),
    pytest.param(TiltAlwaysWarns, NO_WARNING_CASES, id="always-warns"),
    pytest.param(TiltFromRollOnly, {PITCH_20, PITCH_30, BOTH_12}, id="roll-only"),
    pytest.param(TiltFromPitchOnly, {ROLL_20, ROLL_30, BOTH_12}, id="pitch-only"),
    pytest.param(TiltThatRaises, {"callbacks raised no errors"}, id="callback-raises"),
]
TILT_INTRUDER = "no other node publishes on /imu or /safety/tilt_warning"  # see the last test


def test_tilt_checker_accepts_the_reference_and_every_criterion_has_a_wrong_solution(rt):
    report = check_tilt_warning(solution.TiltMonitor, rt)
    assert report.passed, report.summary()
    assert_reference_criteria("check_tilt_warning", report)
    names = {c.name for c in report.criteria}
    assert NO_WARNING_CASES | {ROLL_20, ROLL_30, PITCH_20, PITCH_30, BOTH_12} <= names


@pytest.mark.parametrize("wrong, failing", TILT_WRONG)
def test_tilt_checker_fails_each_criterion_on_a_wrong_solution(rt, wrong, failing):
    report = check_tilt_warning(wrong, rt)
    assert not report.passed
    assert failing <= _failed(report), report.summary()


def test_tilt_checker_gives_up_quickly_on_a_wrong_type_or_a_raising_callback(rt):
    for wrong in (TiltOnBoolTopic, TiltThatRaises):
        start = time.monotonic()
        assert not check_tilt_warning(wrong, rt).passed
        assert time.monotonic() - start < 6, wrong.__name__


def test_tilt_hints_point_to_the_text_without_giving_the_code(rt):
    report = check_tilt_warning(TiltOnImuData, rt)
    hints = " ".join(c.hint for c in report.criteria if not c.passed)
    assert "TODO 2" in hints
    assert "create_subscription(" not in hints and "'/imu'" not in hints


# ---------------------------------------------------------------------- exercise 2: CSV logger
class LoggerNeedsTwoPaths(solution.CmdVelCsvLogger):
    """Wrong: a constructor with an extra argument."""

    def __init__(self, csv_path, backup_path):
        super().__init__(csv_path)


class LoggerOfStrings(solution.CmdVelCsvLogger):
    """Wrong: subscribes to /cmd_vel with the wrong message type."""

    def __init__(self, csv_path):
        super().__init__(csv_path)
        self.destroy_subscription(self.subscription)
        self.subscription = self.create_subscription(String, "/cmd_vel", self.on_twist, 10)


class LoggerWithoutFlush(solution.CmdVelCsvLogger):
    """Wrong: never flushes, so the rows wait in the file's buffer."""

    def on_twist(self, msg):
        self.writer.writerow([time.time(), msg.linear.x, msg.linear.y, msg.linear.z,
                              msg.angular.x, msg.angular.y, msg.angular.z])


class LoggerWithoutHeader(solution.CmdVelCsvLogger):
    """Wrong: no header row."""

    def __init__(self, csv_path):
        super().__init__(csv_path)
        self.file.seek(0)
        self.file.truncate()


class LoggerWritingTwice(solution.CmdVelCsvLogger):
    """Wrong: writes every message twice (once as it arrives, once more 'to be safe')."""

    def on_twist(self, msg):
        super().on_twist(msg)
        super().on_twist(msg)


class LoggerMissingAngularZ(solution.CmdVelCsvLogger):
    """Wrong: forgets the last column, in the header and in the rows."""

    def __init__(self, csv_path):
        super().__init__(csv_path)
        self.file.seek(0)
        self.file.truncate()
        self.writer = csv.writer(self.file)
        self.writer.writerow(solution.CSV_COLUMNS[:-1])
        self.file.flush()

    def on_twist(self, msg):
        self.writer.writerow([time.time(), msg.linear.x, msg.linear.y, msg.linear.z,
                              msg.angular.x, msg.angular.y])
        self.file.flush()


class LoggerOnTheWallClock(solution.CmdVelCsvLogger):
    """Wrong: stamps rows with time.time(), the wall clock, not the node's clock: in a replay or a
    simulation the rows would not line up with the messages' time."""

    def on_twist(self, msg):
        self.writer.writerow([time.time(), msg.linear.x, msg.linear.y, msg.linear.z,
                              msg.angular.x, msg.angular.y, msg.angular.z])
        self.file.flush()


TIME_S = "time_s is the receive time on the node's clock, in seconds"


class LoggerOnTheMonotonicClock(solution.CmdVelCsvLogger):
    """Wrong: stamps rows with time.monotonic(), seconds since boot rather than since the epoch."""

    def on_twist(self, msg):
        self.writer.writerow([time.monotonic(), msg.linear.x, msg.linear.y, msg.linear.z,
                              msg.angular.x, msg.angular.y, msg.angular.z])
        self.file.flush()


class LoggerThatRaises(solution.CmdVelCsvLogger):
    """Wrong: reads a field a Twist does not have; the callback raises."""

    def on_twist(self, msg):
        self.writer.writerow([time.time(), msg.linear.x, msg.linear.w])


CSV_WRONG = [
    pytest.param(LoggerNeedsTwoPaths, {"the node starts"}, id="constructor-argument"),
    pytest.param(LoggerOfStrings, {"subscribes to /cmd_vel with type geometry_msgs/msg/Twist"},
                 id="wrong-type"),
    pytest.param(LoggerWithoutFlush, {"rows are on disk while the node runs"}, id="no-flush"),
    pytest.param(LoggerWithoutHeader, {"header row is " + ",".join(solution.CSV_COLUMNS)}, id="no-header"),
    pytest.param(LoggerWritingTwice, {"one row per message (5)"}, id="two-rows"),
    pytest.param(LoggerMissingAngularZ, {"velocities in the right columns, in message order"},
                 id="missing-column"),
    pytest.param(LoggerOnTheMonotonicClock, {TIME_S}, id="monotonic-clock"),
    pytest.param(LoggerOnTheWallClock, {TIME_S}, id="wall-clock"),
    pytest.param(LoggerThatRaises, {"callbacks raised no errors"}, id="callback-raises"),
]
CSV_INTRUDER = "no other node publishes on /cmd_vel"  # see the last test


def test_csv_checker_accepts_the_reference_and_every_criterion_has_a_wrong_solution(rt):
    report = check_cmd_vel_logger(solution.CmdVelCsvLogger, rt)
    assert report.passed, report.summary()
    assert_reference_criteria("check_cmd_vel_logger", report)


@pytest.mark.parametrize("wrong, failing", CSV_WRONG)
def test_csv_checker_fails_each_criterion_on_a_wrong_solution(rt, wrong, failing):
    report = check_cmd_vel_logger(wrong, rt)
    assert not report.passed
    assert failing <= _failed(report), report.summary()


# ---------------------------------------------------------------------- exercise 3: throughput
def _load_without_size(n_sensors, rate_hz, message_bytes):
    return n_sensors * rate_hz, n_sensors * rate_hz


def _measure_only_messages(node, topics, duration_s=2.0):
    return solution.measure_load(node, topics, duration_s)[0]


def _measure_one_topic(node, topics, duration_s=2.0):
    return solution.measure_load(node, topics[:1], duration_s)


def _measure_messages_as_bytes(node, topics, duration_s=2.0):
    messages_per_s, _ = solution.measure_load(node, topics, duration_s)
    return messages_per_s, messages_per_s


EXPECTED = {"expected_load(10, 100, 324) = (1000 msg/s, 324,000 B/s)",
            "expected_load(3, 30, 921600) = (90 msg/s, 82,944,000 B/s)",
            "expected_load(1, 1, 0) = (1 msg/s, 0 B/s)"}
THROUGHPUT_WRONG = [
    pytest.param(_load_without_size, _measure_only_messages,
                 EXPECTED | {"measure_load(node, topics, duration_s) returns (messages/s, bytes/s)"},
                 id="no-size-and-one-number"),
    pytest.param(solution.expected_load, _measure_one_topic,
                 {"measured messages/s matches what arrived in this kernel meanwhile (within 15%)",
                  "computed (1000 msg/s) and measured agree within 25%"},
                 id="one-topic"),
    pytest.param(solution.expected_load, _measure_messages_as_bytes,
                 {"measured bytes/s ÷ messages/s is the message size (324 B, within 5%)"},
                 id="messages-as-bytes"),
]


@pytest.mark.timing  # the measured criteria are judged by the timing verdict
def test_throughput_checker_accepts_the_reference_and_every_criterion_has_a_wrong_solution(rt):
    report = check_throughput(solution.expected_load, solution.measure_load, rt)
    assert report.passed, report.summary()
    assert_reference_criteria("check_throughput", report)
    assert not rt.children()


@pytest.mark.timing
@pytest.mark.parametrize("expected_load, measure_load, failing", THROUGHPUT_WRONG)
def test_throughput_checker_fails_each_criterion_on_a_wrong_solution(rt, expected_load, measure_load,
                                                                     failing):
    report = check_throughput(expected_load, measure_load, rt, duration_s=0.5)
    assert not report.passed
    assert failing <= _failed(report), report.summary()
    assert not rt.children()


@pytest.mark.timing  # the measured scenario runs (and is judged) even when the functions raise
def test_throughput_checker_reports_exceptions_as_failures(rt):
    def not_done(*_args):
        raise NotImplementedError("TODO")

    report = check_throughput(not_done, not_done, rt, duration_s=0.5)
    assert not report.passed
    assert "NotImplementedError" in report.summary()


# ---------------------------------------------------------------------- both topic checkers
def test_checkers_refuse_to_run_beside_other_publishers(rt):
    rt.add(ImuPublisher)
    report = check_tilt_warning(solution.TiltMonitor, rt)
    assert TILT_INTRUDER in _failed(report)
    assert "also published by /imu_driver" in report.summary()
    rt.remove("/imu_driver")
    rt.add(CmdVelPublisher)
    report = check_cmd_vel_logger(solution.CmdVelCsvLogger, rt)
    assert CSV_INTRUDER in _failed(report)
    assert "also published by /teleop" in report.summary()


COVERED = {  # the intruder criteria fail in test_checkers_refuse_to_run_beside_other_publishers
    "check_tilt_warning": _covered(TILT_WRONG) | {TILT_INTRUDER},
    "check_cmd_vel_logger": _covered(CSV_WRONG) | {CSV_INTRUDER},
    "check_throughput": set().union(*(param.values[2] for param in THROUGHPUT_WRONG)),
}
ONLY_WHEN_FAILING = {"check_tilt_warning": {"scripted attitudes"}}
