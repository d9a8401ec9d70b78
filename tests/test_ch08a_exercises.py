"""Chapter 08a's exercise checkers: each accepts the reference solution, and every criterion of every
checker fails on a plausible wrong solution (real nodes: the student's in this process, the drivers
in child processes). Wrong parts that fail different criteria share one run where the checker goes
on after the first failure."""

from __future__ import annotations

import pytest
from nav_msgs.msg import Odometry
from rclpy.duration import Duration
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import (
    QoSDurabilityPolicy,
    QoSHistoryPolicy,
    QoSLivelinessPolicy,
    QoSProfile,
    QoSReliabilityPolicy,
    qos_policy_name_from_kind,
)
from rclpy.qos_overriding_options import QoSOverridingOptions
from std_msgs.msg import Bool, String

from course_helpers.chapters.ch08_qos.liveliness import blind_spells, seconds_without_writer, watched_downtime
from course_helpers.checks.ch08_qos import DIAGNOSIS, OVERRIDE, check_channel_qos, check_mismatched_subscriber
from course_helpers.checks.ch08_qos_events import check_deadline_watchdog, check_heartbeat
from course_helpers.notebook.solution import solution_source
from course_helpers.solutions import ch08_qos as reference
from course_helpers.solutions import ch08_qos_events as events_reference

from .criteria_registry import assert_reference_criteria

# measures time (rates, latencies, DDS events): make test's timing stage, few workers beside it
pytestmark = pytest.mark.timing

CREATED = "the node can be created"
BEST_EFFORT, RELIABLE = QoSReliabilityPolicy.BEST_EFFORT, QoSReliabilityPolicy.RELIABLE
VOLATILE, TRANSIENT_LOCAL = QoSDurabilityPolicy.VOLATILE, QoSDurabilityPolicy.TRANSIENT_LOCAL


def _failed(report) -> list[str]:
    return [c.name for c in report.criteria if not c.passed]


# ---------------------------------------------------------------- 08.1: QoS for four channels
CAMERA_FRESH = "camera: frames stay fresh at a consumer that needs 150 ms per frame (median age < 250 ms)"


NOT_A_DICT = ["profiles is a dict of channel -> QoSProfile"]
UNFINISHED = ["one QoSProfile for each of camera, lidar, joint_states, estop"]
EVERYTHING_WRONG = [  # what test_channel_checker_rejects_resending_queueing_latching_and_lossy_choices fails
    "camera: a lost frame is not resent (a late frame is worthless)",
    CAMERA_FRESH,
    "lidar: a consumer with your profile receives scans from a driver that publishes with "
    "qos_profile_sensor_data",
    "lidar: a node that starts later gets no old scan",
    "lidar: only recent scans are queued (a depth of 10 at most)",
    "joint_states: a node that starts later gets no old state",
    "joint_states: only recent states are queued (a depth of 10 at most)",
    "estop: a press lost on the way is sent again",
    "estop: a controller that starts after the button was pressed still gets it",
    "estop: a safety monitor requesting RELIABLE + TRANSIENT_LOCAL connects",
]


def test_channel_checker_accepts_the_reference_solution_and_its_report_names_no_choice(rt):
    report = check_channel_qos(reference.channel_qos(), rt)
    assert report.passed, report.summary()
    assert_reference_criteria("check_channel_qos", report)
    assert rt.nodes() == [] and rt.children() == {}
    # what passing looks like (saved in the notebook) says what was checked, not which QoS passed it
    text = report.summary()
    for choice in ("BEST_EFFORT", "KEEP_LAST", "VOLATILE", "you chose"):
        assert choice not in text, text
    assert "RELIABLE" not in text.replace("RELIABLE subscription", "").replace("RELIABLE + TRANSIENT", "")


def test_channel_checker_rejects_what_is_not_one_profile_per_channel(rt):
    not_a_dict = check_channel_qos(list(reference.channel_qos().values()), rt)
    assert _failed(not_a_dict) == NOT_A_DICT, not_a_dict.summary()
    unfinished = check_channel_qos({"camera": QoSProfile(depth=1), "lidar": None}, rt)
    assert _failed(unfinished) == UNFINISHED


def test_channel_checker_rejects_resending_queueing_latching_and_lossy_choices(rt):
    wrong = {  # everything reliable and kept where it should not be, lossy where it must not be
        "camera": QoSProfile(history=QoSHistoryPolicy.KEEP_ALL, reliability=RELIABLE),
        "lidar": QoSProfile(history=QoSHistoryPolicy.KEEP_ALL, reliability=RELIABLE,
                            durability=TRANSIENT_LOCAL),
        "joint_states": QoSProfile(history=QoSHistoryPolicy.KEEP_ALL, reliability=RELIABLE,
                                   durability=TRANSIENT_LOCAL),
        "estop": QoSProfile(depth=1, reliability=BEST_EFFORT, durability=VOLATILE),
    }
    report = check_channel_qos(wrong, rt)
    assert _failed(report) == EVERYTHING_WRONG, report.summary()


def test_channel_checker_gives_a_reliable_volatile_estop_nothing_for_a_late_controller(rt):
    """The live late joiner, judged with DDS's acknowledgements and a sentinel: no window to wait out."""
    profiles = {**reference.channel_qos(), "estop": QoSProfile(depth=1, reliability=RELIABLE,
                                                                durability=VOLATILE)}
    report = check_channel_qos(profiles, rt)
    assert _failed(report) == EVERYTHING_WRONG[-2:], report.summary()  # the late joiner; the monitor
    assert "the late joiner got nothing" in report.summary()


def test_channel_checker_measures_the_stale_frames_behind_a_deep_camera_queue(rt):
    profiles = {**reference.channel_qos(), "camera": QoSProfile(depth=30, reliability=BEST_EFFORT)}
    report = check_channel_qos(profiles, rt)
    assert _failed(report) == [CAMERA_FRESH], report.summary()
    fresh = next(c for c in report.criteria if c.name == CAMERA_FRESH)
    assert fresh.detail.startswith("median age") and "KEEP_LAST" not in fresh.detail


# ---------------------------------------------------------------- 08.2: the mismatched subscriber
class _Listener(Node):
    """A right listener whose parts the wrong ones below change one at a time: the QoS and topic are
    given, a deployer may override its reliability, and it names the policy of an incompatible-QoS event."""

    def __init__(self, qos=None, topic="/robot_cmd", parameter_overrides=(), diagnose=True, overridable=True):
        super().__init__("robot_listener", parameter_overrides=list(parameter_overrides))
        self.received = []
        self.incompatible = []
        events = SubscriptionEventCallbacks(incompatible_qos=self.on_incompatible_qos) if diagnose else None
        options = QoSOverridingOptions.with_default_policies() if overridable else None
        self.subscription = self.create_subscription(
            String, topic, self.on_cmd, qos or QoSProfile(depth=10, reliability=BEST_EFFORT),
            event_callbacks=events, qos_overriding_options=options)

    def on_cmd(self, msg):
        self.received.append(msg.data)

    def on_incompatible_qos(self, status):
        self.incompatible.append(qos_policy_name_from_kind(status.last_policy_kind))


class StarterListener(_Listener):
    """The starting code: reliable and transient local, which the controller does not offer, and no
    incompatible-QoS callback yet."""

    def __init__(self, parameter_overrides=()):
        super().__init__(QoSProfile(depth=10, reliability=RELIABLE, durability=TRANSIENT_LOCAL),
                         parameter_overrides=parameter_overrides, diagnose=False)


class NamedListener(_Listener):
    """Its constructor wants an argument the checker cannot give."""

    def __init__(self, name):
        super().__init__()


class TypoListener(_Listener):
    def __init__(self, parameter_overrides=()):
        super().__init__(topic="/robot_command", parameter_overrides=parameter_overrides)


class ForgetfulListener(_Listener):
    """Compatible, but keeps nothing."""

    def on_cmd(self, msg):
        pass


class RenamedListener(Node):
    """Compatible, but keeps the commands in self.commands."""

    def __init__(self):
        super().__init__("robot_listener")
        self.commands = []
        self.create_subscription(String, "/robot_cmd", lambda m: self.commands.append(m.data),
                                 QoSProfile(depth=10, reliability=BEST_EFFORT))


class WholeMessageListener(_Listener):
    """Keeps the message objects instead of the commands they carry."""

    def on_cmd(self, msg):
        self.received.append(msg)


class ListenerWithoutOverrides(_Listener):
    """The old constructor: takes no parameter_overrides, so a deployer's override never reaches it."""

    def __init__(self):
        super().__init__()


class ListenerNotOverridable(_Listener):
    """Takes parameter_overrides, but its subscription has no qos_overriding_options: the override is
    a parameter nobody reads."""

    def __init__(self, parameter_overrides=()):
        super().__init__(parameter_overrides=parameter_overrides, overridable=False)


class ListenerThatDiagnosesNothing(_Listener):
    """Does everything but the diagnosis: the right QoS, the overrides, self.incompatible, and no
    incompatible-QoS callback (rclpy's default only logs a warning)."""

    def __init__(self, parameter_overrides=()):
        super().__init__(parameter_overrides=parameter_overrides, diagnose=False)


class ListenerKeepingTheStatus(_Listener):
    """Keeps the event's whole status instead of the policy it names."""

    def on_incompatible_qos(self, status):
        self.incompatible.append(status)


STARTER_FAILS = ["its QoS is compatible with what the publisher offers", "its callback gets the commands",
                 OVERRIDE, DIAGNOSIS]
LISTENER_WRONG = {  # each wrong listener, and the criteria it fails (exactly those)
    NamedListener: ["the node starts"],
    TypoListener: ["it subscribes to /robot_cmd"],
    RenamedListener: ["it keeps what it receives in self.received"],
    ForgetfulListener: ["its callback gets the commands"],
    WholeMessageListener: ["they are the controller's commands"],
    ListenerWithoutOverrides: [OVERRIDE, DIAGNOSIS],
    ListenerNotOverridable: [OVERRIDE, DIAGNOSIS],
    ListenerThatDiagnosesNothing: [DIAGNOSIS],
    ListenerKeepingTheStatus: [DIAGNOSIS],
}


def test_mismatched_subscriber_checker_accepts_the_reference_solution(rt):
    report = check_mismatched_subscriber(reference.RobotCmdListener, rt)
    assert report.passed, report.summary()
    assert_reference_criteria("check_mismatched_subscriber", report)
    assert "the event named RELIABILITY" in report.summary()
    assert rt.nodes() == [] and rt.children() == {}


def test_mismatched_subscriber_checker_rejects_the_starting_code_without_giving_the_fix(rt):
    report = check_mismatched_subscriber(StarterListener, rt)
    assert _failed(report) == STARTER_FAILS, report.summary()
    compatible = report.criteria[1]
    assert "reliability" in compatible.detail and "durability" in compatible.detail
    for answer in ("best_effort", "volatile", "BEST_EFFORT", "VOLATILE"):  # what to write is not said
        assert answer not in compatible.detail + compatible.hint
    assert rt.nodes() == [] and rt.children() == {}


@pytest.mark.parametrize("wrong", LISTENER_WRONG, ids=[wrong.__name__ for wrong in LISTENER_WRONG])
def test_mismatched_subscriber_checker_rejects_each_wrong_part(rt, wrong):
    report = check_mismatched_subscriber(wrong, rt)
    assert _failed(report) == LISTENER_WRONG[wrong], report.summary()
    assert rt.nodes() == [] and rt.children() == {}


def test_the_diagnosis_criterion_says_what_the_event_named_and_what_the_node_kept(rt):
    report = check_mismatched_subscriber(ListenerKeepingTheStatus, rt)
    [diagnosis] = [c for c in report.criteria if c.name == DIAGNOSIS]
    assert diagnosis.detail.startswith("the event named RELIABILITY; self.incompatible holds "), diagnosis
    assert "on_incompatible_qos" not in diagnosis.hint and "last_policy_kind" not in diagnosis.hint


# ---------------------------------------------------------------- 08.3: the deadline watchdog
WATCHED = QoSProfile(depth=10, deadline=Duration(seconds=0.5))


class _Watchdog(Node):
    """A right watchdog whose parts the wrong ones below change one at a time."""

    def __init__(self, qos=WATCHED, odom_type=Odometry, alarm_type=String):
        super().__init__("odom_watchdog")
        self.alarm_type = alarm_type
        self.alarm = self.create_publisher(alarm_type, "alarm", 10)
        self.subscription = self.create_subscription(
            odom_type, "odom", lambda _m: None, qos,
            event_callbacks=SubscriptionEventCallbacks(deadline=self.on_deadline_missed))

    def on_deadline_missed(self, _status) -> None:
        self.alarm.publish(self.alarm_type())


class NamedWatchdog(_Watchdog):
    def __init__(self, name):
        super().__init__()


class StringOdomWatchdog(_Watchdog):
    def __init__(self):
        super().__init__(odom_type=String)


class TimerWatchdog(Node):
    """Watches /odom with a timer of its own instead of a QoS deadline."""

    def __init__(self):
        super().__init__("odom_watchdog")
        self.last = None
        self.alarm = self.create_publisher(String, "alarm", 10)
        self.subscription = self.create_subscription(Odometry, "odom", self.on_odom, 10)
        self.timer = self.create_timer(0.1, self.check)  # period in seconds

    def on_odom(self, _msg) -> None:
        self.last = self.get_clock().now()

    def check(self) -> None:
        if self.last and (self.get_clock().now() - self.last).nanoseconds > 0.5e9:
            self.alarm.publish(String(data="no odometry"))


class BeltAndBracesWatchdog(TimerWatchdog):
    """Requests the deadline, but still watches with a timer of its own."""

    def __init__(self):
        super().__init__()
        self.destroy_subscription(self.subscription)
        self.subscription = self.create_subscription(Odometry, "odom", self.on_odom, WATCHED)


class LatchedWatchdog(_Watchdog):
    """Asks for the last odometry on joining (transient local), which the driver does not offer."""

    def __init__(self):
        super().__init__(QoSProfile(depth=10, deadline=Duration(seconds=0.5), durability=TRANSIENT_LOCAL))


class BoolAlarmWatchdog(_Watchdog):
    def __init__(self):
        super().__init__(alarm_type=Bool)


class SilentWatchdog(Node):
    """Requests the deadline but never raises the alarm."""

    def __init__(self):
        super().__init__("odom_watchdog")
        self.alarm = self.create_publisher(String, "alarm", 10)
        self.subscription = self.create_subscription(Odometry, "odom", lambda _m: None, WATCHED)


class NoisyWatchdog(_Watchdog):
    """Sounds the alarm on every message (and on every missed deadline)."""

    def __init__(self):
        super().__init__()
        self.destroy_subscription(self.subscription)
        self.subscription = self.create_subscription(
            Odometry, "odom", self.on_deadline_missed, WATCHED,
            event_callbacks=SubscriptionEventCallbacks(deadline=self.on_deadline_missed))


WATCHDOG_WRONG = {  # each wrong watchdog, and the criteria it fails (exactly those)
    NamedWatchdog: [CREATED],
    StringOdomWatchdog: ["it subscribes to /odom (nav_msgs/msg/Odometry)"],
    TimerWatchdog: ["the subscription requests a deadline (0.2 s to 1 s)"],
    BeltAndBracesWatchdog: ["it leaves the watching to DDS (no timer of its own)"],
    LatchedWatchdog: ["its QoS is compatible with the odometry driver (reliable, deadline 0.2 s)"],
    BoolAlarmWatchdog: ["it publishes on /alarm (std_msgs/msg/String)"],
}
WATCHDOG_TIMED_WRONG = {  # the same, for the two that get as far as the driver's run
    SilentWatchdog: ["an alarm within 1.5 s after the odometry stopped"],
    NoisyWatchdog: ["no alarm while odometry arrives every 0.1 s", "no alarm once odometry flows again"],
}


def test_watchdog_checker_accepts_the_reference_solution(rt):
    report = check_deadline_watchdog(events_reference.OdomWatchdog, rt)
    assert report.passed, report.summary()
    assert_reference_criteria("check_deadline_watchdog", report)
    assert rt.nodes() == [] and rt.children() == {}


def test_watchdog_checker_rejects_each_wrong_part_before_running_the_driver(rt):
    for wrong, criteria in WATCHDOG_WRONG.items():
        report = check_deadline_watchdog(wrong, rt)
        assert _failed(report) == criteria, (wrong.__name__, report.summary())
    assert rt.children() == {}


def test_watchdog_checker_rejects_a_watchdog_that_never_alarms_or_always_does(rt):
    for wrong, criteria in WATCHDOG_TIMED_WRONG.items():
        report = check_deadline_watchdog(wrong, rt)
        assert _failed(report) == criteria, (wrong.__name__, report.summary())


# ---------------------------------------------------------------- 08.4: heartbeat and monitor
BEAT = events_reference.HEARTBEAT_QOS


class NamedHeartbeat(events_reference.SwitchableHeartbeat):
    def __init__(self, name):
        super().__init__()


class NamedMonitor(events_reference.HeartbeatMonitor):
    def __init__(self, name):
        super().__init__()


class BoolHeartbeat(Node):
    """Beats on /heartbeat with the wrong type."""

    def __init__(self):
        super().__init__("heartbeat")
        self.publisher = self.create_publisher(Bool, "heartbeat", BEAT)


class MisspeltMonitor(events_reference.HeartbeatMonitor):
    """Watches /heartbeats instead of /heartbeat."""

    def __init__(self):
        super().__init__()
        self.destroy_subscription(self.subscription)
        self.subscription = self.create_subscription(String, "heartbeats", self.on_beat, BEAT)


class AutomaticHeartbeat(Node):
    """Publishes with AUTOMATIC liveliness: the process, not the writer, keeps it alive."""

    def __init__(self):
        super().__init__("heartbeat")
        qos = QoSProfile(depth=1, liveliness=QoSLivelinessPolicy.AUTOMATIC,
                         liveliness_lease_duration=Duration(seconds=0.5))
        self.publisher = self.create_publisher(String, "heartbeat", qos)


class ImpatientMonitor(events_reference.HeartbeatMonitor):
    """Requests a 0.2 s lease, shorter than the 0.5 s the heartbeat promises."""

    def __init__(self):
        super().__init__()
        self.destroy_subscription(self.subscription)
        impatient = QoSProfile(depth=1, liveliness=QoSLivelinessPolicy.MANUAL_BY_TOPIC,
                               liveliness_lease_duration=Duration(seconds=0.2))
        self.subscription = self.create_subscription(
            String, "heartbeat", self.on_beat, impatient,
            event_callbacks=SubscriptionEventCallbacks(liveliness=self.on_liveliness))


class DeafHeartbeat(events_reference.SwitchableHeartbeat):
    """Beats, but listens to no command."""

    def __init__(self):
        super().__init__()
        self.destroy_subscription(self.enable)


class MuteMonitor(events_reference.HeartbeatMonitor):
    """Watches, but has no status publisher (it only logs)."""

    def __init__(self):
        super().__init__()
        self.destroy_publisher(self.status)


class NeverBeatingHeartbeat(events_reference.SwitchableHeartbeat):
    """Its timer never asserts: it starts disabled and waits for a True."""

    def __init__(self):
        super().__init__()
        self.beating = False


class AlarmistMonitor(events_reference.HeartbeatMonitor):
    """Says 'lost' on every liveliness event, the first 'alive' included."""

    def on_liveliness(self, status) -> None:
        self.status.publish(String(data="lost"))
        if status.alive_count_change > 0:
            self.status.publish(String(data="alive"))


class SeldomHeartbeat(events_reference.SwitchableHeartbeat):
    """Asserts every 2 s, four times the 0.5 s lease it promises."""

    def __init__(self):
        super().__init__()
        self.destroy_timer(self.timer)
        self.timer = self.create_timer(2.0, self.beat)  # period in seconds


class LostOnlyMonitor(events_reference.HeartbeatMonitor):
    """Reports losses, never a return."""

    def on_liveliness(self, status) -> None:
        if status.not_alive_count_change > 0:
            self.status.publish(String(data="lost"))


class StubbornHeartbeat(events_reference.SwitchableHeartbeat):
    """Ignores the command to stop."""

    def on_enable(self, msg) -> None:
        pass


class DeafMonitor(Node):
    """Subscribes to the heartbeat and publishes a status topic, but has no liveliness callback."""

    def __init__(self):
        super().__init__("heartbeat_monitor")
        self.status = self.create_publisher(String, "heartbeat/status", 10)
        self.subscription = self.create_subscription(String, "heartbeat", lambda _m: None, BEAT)


class OneWayHeartbeat(events_reference.SwitchableHeartbeat):
    """Stops on False, and never starts again."""

    def on_enable(self, msg) -> None:
        if not msg.data:
            self.beating = False


HEARTBEAT_WRONG = {  # each pair of wrong nodes, and the criteria it fails (exactly those)
    (NamedHeartbeat, NamedMonitor): [CREATED, CREATED],
    (BoolHeartbeat, MisspeltMonitor): ["heartbeat: it has a publisher on /heartbeat (std_msgs/msg/String)",
                                       "monitor: it subscribes to /heartbeat (std_msgs/msg/String)"],
    (AutomaticHeartbeat, ImpatientMonitor): [
        "heartbeat: MANUAL_BY_TOPIC with a lease of at most 1 s",
        "monitor: compatible with a MANUAL_BY_TOPIC heartbeat, lease 0.5 s"],
    (DeafHeartbeat, MuteMonitor): ["heartbeat: it subscribes to /heartbeat/enable (std_msgs/msg/Bool)",
                                   "monitor: it publishes on /heartbeat/status (std_msgs/msg/String)"],
}
HEARTBEAT_TIMED_WRONG = {  # the same for pairs that get as far as the timed scenarios (one test each)
    (NeverBeatingHeartbeat, AlarmistMonitor): [
        "heartbeat: a monitor sees it alive",
        "monitor: says nothing is lost while the heartbeat asserts every 0.1 s"],
    (SeldomHeartbeat, LostOnlyMonitor): ["heartbeat: alive through 6 leases, with at most 1 of them lost",
                                         "monitor: publishes 'alive' when the heartbeat is back"],
    (StubbornHeartbeat, DeafMonitor): ["heartbeat: lost within 2 s of a False on /heartbeat/enable",
                                       "monitor: publishes 'lost' within 2 s after the heartbeat stopped",
                                       "monitor: publishes 'alive' when the heartbeat is back"],
    (OneWayHeartbeat, events_reference.HeartbeatMonitor): ["heartbeat: alive again after a True"],
}


def _fails_exactly_its_criteria(rt, heartbeat, monitor, table) -> None:
    report = check_heartbeat(heartbeat, monitor, rt)
    assert _failed(report) == table[heartbeat, monitor], (heartbeat.__name__, monitor.__name__,
                                                          report.summary())


def test_heartbeat_checker_accepts_the_reference_solution(rt):
    report = check_heartbeat(events_reference.SwitchableHeartbeat, events_reference.HeartbeatMonitor, rt)
    assert report.passed, report.summary()
    assert_reference_criteria("check_heartbeat", report)
    assert rt.nodes() == [] and rt.children() == {}


def test_heartbeat_checker_rejects_wrong_endpoints_and_qos(rt):
    for heartbeat, monitor in HEARTBEAT_WRONG:
        _fails_exactly_its_criteria(rt, heartbeat, monitor, HEARTBEAT_WRONG)
    assert rt.children() == {}


def test_heartbeat_checker_rejects_a_silent_heartbeat_and_an_alarmist_monitor(rt):
    _fails_exactly_its_criteria(rt, NeverBeatingHeartbeat, AlarmistMonitor, HEARTBEAT_TIMED_WRONG)


def test_time_without_a_writer_counts_only_the_window_and_starts_from_the_last_state_before_it():
    changes = [(0.0, 1), (2.0, 0), (2.5, 1), (4.5, 0), (9.0, 1)]
    assert seconds_without_writer(changes, 1.0, 5.0) == pytest.approx(1.0)  # 2.0-2.5 and 4.5-5.0
    assert seconds_without_writer(changes, 3.0, 4.0) == pytest.approx(0.0)  # alive throughout
    assert seconds_without_writer(changes, 2.2, 2.4) == pytest.approx(0.2)  # lost before the window began
    assert seconds_without_writer([], 0.0, 3.0) == pytest.approx(3.0)  # never alive
    assert seconds_without_writer(changes, 4.0, 12.0) == pytest.approx(4.5)  # 4.5-9.0


def test_time_the_watcher_could_not_see_is_left_out_of_the_judgement():
    # A heartbeat asserting every 2 s with a 0.5 s lease: alive 0-0.5, 2.0-2.5, 4.0-4.5. The watcher's
    # executor was held up from 0.4 s to 1.9 s, so the loss at 0.5 s reached it only at 1.9 s.
    changes = [(0.0, 1), (1.9, 0), (2.0, 1), (2.5, 0), (4.0, 1)]
    ticks = [t / 100 for t in range(0, 451, 5) if not 40 < t < 190]
    assert blind_spells(ticks, 0.0, 4.5, 0.15) == [(0.4, 1.9)]
    assert seconds_without_writer(changes, 0.0, 3.0) == pytest.approx(0.6)  # what the late event made of it
    down, seen = watched_downtime(changes, ticks, 0.0, 4.5, 0.15)
    assert seen == pytest.approx(3.0) and down == pytest.approx(1.6)  # 1.9-2.0 and 2.5-4.0
    assert down > 1 / 6 * seen  # more than one of six leases: the checker's verdict is a failure
    assert seconds_without_writer(changes, 0.0, 4.5, [(0.0, 4.5)]) == 0.0  # nothing seen, nothing judged


def test_heartbeat_checker_rejects_a_seldom_heartbeat_and_a_monitor_that_never_says_alive(rt):
    _fails_exactly_its_criteria(rt, SeldomHeartbeat, LostOnlyMonitor, HEARTBEAT_TIMED_WRONG)


def test_heartbeat_checker_rejects_a_heartbeat_that_ignores_the_command_and_a_deaf_monitor(rt):
    _fails_exactly_its_criteria(rt, StubbornHeartbeat, DeafMonitor, HEARTBEAT_TIMED_WRONG)


def test_heartbeat_checker_rejects_a_heartbeat_that_never_comes_back(rt):
    _fails_exactly_its_criteria(rt, OneWayHeartbeat, events_reference.HeartbeatMonitor, HEARTBEAT_TIMED_WRONG)


def test_the_solutions_are_offered_by_show_solution():
    assert "class RobotCmdListener(Node)" in solution_source("ch08_qos", "RobotCmdListener")
    for name in ("OdomWatchdog", "SwitchableHeartbeat", "HeartbeatMonitor"):
        assert f"class {name}(Node)" in solution_source("ch08_qos_events", name)
    assert "def channel_qos()" in solution_source("ch08_qos", "channel_qos")


COVERED = {
    "check_channel_qos": set(NOT_A_DICT + UNFINISHED + EVERYTHING_WRONG),
    "check_mismatched_subscriber": set(STARTER_FAILS).union(*LISTENER_WRONG.values()),
    "check_deadline_watchdog": set().union(*WATCHDOG_WRONG.values(), *WATCHDOG_TIMED_WRONG.values()),
    "check_heartbeat": set().union(*HEARTBEAT_WRONG.values(), *HEARTBEAT_TIMED_WRONG.values()),
}
ONLY_WHEN_FAILING = {
    "check_channel_qos": set(NOT_A_DICT),
    "check_mismatched_subscriber": {"the node starts"},
    "check_deadline_watchdog": {CREATED},
    "check_heartbeat": {CREATED},
}
