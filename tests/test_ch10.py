"""Chapter 10 (capstone), with real nodes and processes."""

from __future__ import annotations

import math
from collections import deque

import pytest
from action_msgs.msg import GoalStatus
from course_interfaces.action import Navigate
from course_interfaces.msg import EStop
from course_interfaces.srv import PickItem
from geometry_msgs.msg import Point, PointStamped
from rcl_interfaces.srv import SetParameters
from rclpy.action import ActionClient
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from std_srvs.srv import Trigger

from course_helpers import CourseError, WaitTimeout
from course_helpers.chapters import ch10_capstone as cp
from course_helpers.chapters.ch10_capstone.channels import ESTOP_QOS
from course_helpers.checks.ch10_capstone import check_fleet_estop
from course_helpers.core.domains import nodes_in_domain, reserve_spare_domain
from course_helpers.solutions.ch10_capstone import FleetSafetyMonitor
from tests.criteria_registry import assert_reference_criteria
from tests.timing import assert_timing

# measures time (rates, latencies, DDS events): make test's timing stage, few workers beside it
pytestmark = pytest.mark.timing


@pytest.fixture
def robot(rt):
    """Robot 1 without its camera (less CPU), with a mission runner and the operator's button."""
    handle = cp.start_robot(rt, "robot1", camera=False)
    runner = rt.add(cp.MissionRunner, "/robot1", console=False)
    button = rt.add(cp.EStopButton, "/robot1", console=False)
    return handle, runner, button


# ---------------------------------------------------------------------------------- chapter 10
def test_pick_mission_completes(rt, robot):
    _handle, runner, _button = robot
    mission = runner.start("widget-7", shelf="B2")
    progress = []
    mission.listeners.append(lambda m: progress.append(m.progress))
    assert mission.wait(timeout=30), mission.state
    assert mission.steps == ["driving to shelf B2", "reached shelf B2", "picking widget-7",
                             "picked widget-7 from B2", "returning home", "reached home",
                             "placed widget-7", "delivered widget-7"]
    assert mission.progress == 1.0
    assert any(0.05 < p < 0.45 for p in progress), "feedback drove the progress during the first leg"
    pose = rt.get("/robot1/navigator").pose
    assert pose is not None and abs(pose[0]) < 0.1 and abs(pose[1]) < 0.1  # back home
    gripper = rt.get("/robot1/gripper")
    assert gripper.state == "ready" and gripper.holding == "", "the delivered item was put down"
    summary = cp.mission_summary(mission)
    assert summary.splitlines()[0] == "mission widget-7@B2: done: delivered widget-7 (progress 100%)"
    assert summary.splitlines()[1:] == [f"  - {step}" for step in mission.steps]
    assert "<li>placed widget-7</li>" in cp.mission_html(mission)


class LaggingBase(cp.BaseController):
    """A base whose wheels apply each velocity command LAG odometry steps late: a busy robot computer,
    made deterministic (counted in the base's own steps, not in seconds)."""

    LAG = 5  # steps of 50 ms

    def __init__(self, namespace: str = "/laggy"):
        super().__init__(namespace, home=[0.0, 0.0])
        self.steps = 0
        self.pending: deque = deque()  # (step it arrived in, Twist)

    def on_cmd(self, msg) -> None:
        self.pending.append((self.steps, msg))

    def step(self) -> None:
        while self.pending and self.pending[0][0] <= self.steps - self.LAG:
            super().on_cmd(self.pending.popleft()[1])
        self.steps += 1
        super().step()


def test_a_goal_succeeds_only_once_a_lagging_base_has_stopped_at_the_target(rt):
    rt.add(cp.SafetyMonitor, "/laggy", console=False)
    base = rt.add(LaggingBase, "/laggy", console=False)
    navigator = rt.add(cp.Navigator, "/laggy", console=False)
    client = ActionClient(rt.graph, Navigate, "/laggy/navigate")
    try:
        rt.wait_until(lambda: navigator.pose is not None and not navigator.estop_engaged
                      and not base.estop_engaged and client.server_is_ready(), 10,
                      "the lagging base, its navigator and the released e-stop")
        target = (1.0, 0.5)
        request = Navigate.Goal(target=Point(x=target[0], y=target[1]))
        goal = rt.wait_for_future(client.send_goal_async(request), 5, "the goal's acceptance")
        assert goal.accepted
        outcome = rt.wait_for_future(goal.get_result_async(), 30, "the navigation result")
        assert outcome.status == GoalStatus.STATUS_SUCCEEDED
        # success meant: the base had stopped there. Nothing it was told before moves it on afterwards.
        where = (base.x, base.y)
        assert base.vx == base.vy == 0.0 and math.dist(where, target) <= navigator.tolerance, where
        steps = base.steps
        rt.wait_until(lambda: base.steps >= steps + 2 * base.LAG, 10, "the base's commands in flight")
        assert (base.x, base.y) == where, "the base moved on after the navigator reported arrival"
    finally:
        rt.call_in_executor(client.destroy)
        for name in ("navigator", "base", "safety_monitor"):
            rt.remove(f"/laggy/{name}")


def test_place_item_needs_an_item_in_the_gripper(rt, robot):
    client = rt.graph.create_client(Trigger, "/robot1/place_item")
    try:
        assert client.wait_for_service(timeout_sec=5)
        response = rt.wait_for_future(client.call_async(Trigger.Request()), 5)
    finally:
        rt.call_in_executor(rt.graph.destroy_client, client)
    assert not response.success and "empty" in response.message


def test_state_graph_shows_the_boards_hidden_connections(rt, robot):
    handle, _runner, _button = robot
    board = rt.add(cp.StateBoard, "/robot1", console=False)
    nodes = handle.node_names() + ["/robot1/mission_runner"]
    nodes.remove("/robot1/camera")  # started without a camera
    cp.collect_states(rt, board, nodes)
    snap = cp.state_graph(rt, board)
    assert snap.nodes == sorted([*nodes, "/state_board"])
    assert sorted(snap.topics) == sorted(f"{n}/_state" for n in nodes)
    for node in nodes:
        assert snap.publishers(f"{node}/_state") == [node]
        assert snap.subscribers(f"{node}/_state") == ["/state_board"]


def test_pick_fails_away_from_the_shelf(rt, robot):
    client = rt.graph.create_client(PickItem, "/robot1/pick_item")
    try:
        assert client.wait_for_service(timeout_sec=5)
        response = rt.wait_for_future(client.call_async(PickItem.Request(item_id="x", shelf="A2")), 5)
    finally:
        rt.call_in_executor(rt.graph.destroy_client, client)
    assert not response.success and "not at shelf A2" in response.message


def test_estop_stops_every_node_including_a_late_joiner(rt, robot):
    handle, runner, button = robot
    board = rt.add(cp.StateBoard, "/robot1", console=False)
    nodes = handle.node_names() + ["/robot1/mission_runner"]
    nodes.remove("/robot1/camera")  # started without a camera
    mission = runner.start("widget-8", shelf="A2")
    rt.wait_until(lambda: mission.progress > 0.1, 10, "the robot to be under way")
    before = cp.collect_states(rt, board, nodes, until=lambda s: s["/robot1/base"] == "driving")

    assert button.press() == "e-stop engaged"
    after = cp.collect_states(rt, board, nodes, until=lambda s: all(s[n] != before[n] for n in nodes))
    assert after["/robot1/base"] == "halted (e-stop)"
    assert after["/robot1/navigator"] == "goal aborted (e-stop)"
    assert after["/robot1/gripper"] == "locked (e-stop)"
    assert after["/robot1/lidar"] == "scanning (e-stop engaged)"
    assert after["/robot1/safety_monitor"].startswith("ENGAGED by operator")
    assert mission.wait(timeout=5) is False
    assert "aborted (e-stop engaged)" in mission.state

    # The base really stopped: odometry reports zero velocity and the pose no longer changes.
    odom = rt.wait_for_messages("/robot1/odom", "nav_msgs/msg/Odometry", count=5, timeout=3)
    assert all(m.twist.twist.linear.x == 0.0 and m.twist.twist.linear.y == 0.0 for m in odom)
    assert odom[0].pose.pose.position == odom[-1].pose.pose.position

    # A node that starts now, after the e-stop, learns it at once (TRANSIENT_LOCAL) ...
    light = rt.add(cp.StatusLight, "/robot1", console=False)
    rt.wait_until(lambda: light.state == "RED: operator e-stop", 3, "the late joiner to turn red")
    late = cp.collect_states(rt, board, ["/robot1/status_light"])
    assert late["/robot1/status_light"].startswith("RED")
    # ... while a VOLATILE late joiner hears nothing.
    with pytest.raises(WaitTimeout):
        rt.wait_for_messages("/robot1/estop", EStop, timeout=1.0, qos=QoSProfile(depth=10))

    # Goals are refused while engaged; after the release a mission runs again.
    refused = runner.start("widget-9", shelf="A1")
    assert refused.wait(timeout=5) is False and "rejected" in refused.state
    assert button.release() == "e-stop released"
    rt.wait_until(lambda: light.state == "green", 3, "the light to turn green")
    again = runner.start("widget-9", shelf="A1")
    assert again.wait(timeout=30), again.state


def test_lidar_obstacle_engages_the_estop_by_itself(rt):
    rt.spawn("robot1", cp.make_robot_drivers, params={"namespace": "/robot1", "camera": False},
             wait_for="/robot1/safety_monitor")
    light = rt.add(cp.StatusLight, "/robot1", console=False)
    rt.wait_until(lambda: light.state == "green", 5, "the released e-stop")
    # A person steps next to the robot: set the LIDAR's obstacle parameter from a client.
    client = rt.graph.create_client(SetParameters, "/robot1/lidar/set_parameters")
    try:
        assert client.wait_for_service(timeout_sec=5)
        request = SetParameters.Request(parameters=[
            Parameter("obstacles", Parameter.Type.DOUBLE_ARRAY, [0.3, 0.0, 0.1]).to_parameter_msg()])
        rt.wait_for_future(client.call_async(request), 5)
    finally:
        rt.call_in_executor(rt.graph.destroy_client, client)
    rt.wait_until(lambda: light.state == "RED: safety_monitor e-stop", 5, "the automatic e-stop")


def test_two_robots_by_namespace(rt):
    robots = [cp.start_robot(rt, name, camera=False) for name in ("robot1", "robot2")]
    runners = [rt.add(cp.MissionRunner, r.namespace, console=False) for r in robots]
    first, second = runners[0].start("a", shelf="A1"), runners[1].start("b", shelf="B1")
    assert first.wait(timeout=30) and second.wait(timeout=30)
    topics = {t for t, _ in rt.graph.get_topic_names_and_types()}
    for name in ("robot1", "robot2"):
        assert {f"/{name}/cmd_vel", f"/{name}/estop", f"/{name}/odom"} <= topics
    assert "/cmd_vel" not in topics


def test_other_domain_is_invisible(rt):
    domain = reserve_spare_domain()
    assert domain != rt.domain.domain_id
    fleet_b = rt.spawn("fleet_b", cp.make_robot_drivers, params={"namespace": "/robot3", "camera": False},
                       env={"ROS_DOMAIN_ID": str(domain)})
    ready = fleet_b.wait_for_report("ready", 15, "the robot's drivers in the other domain")
    assert "/robot3/base" in ready["nodes"]
    seen = nodes_in_domain(domain, wait_s=8.0, expect=["/robot3/base"])
    assert "/robot3/base" in seen
    assert not any(n.startswith("/robot3") for n in rt.graph_nodes())


def test_missed_frames_count_gaps_and_a_shortfall():
    period = 1 / 30
    every_frame = [i * period for i in range(75)]
    assert cp.count_missed(every_frame, 30, 2.5) == 0
    every_third = every_frame[::3]  # 25 of 75 frames: two lost in each gap, and two after the last
    assert cp.count_missed(every_third, 30, 2.5) == 50
    assert cp.count_missed(every_third, 30, 2.5 - 2 * period) == 2 * (len(every_third) - 1)
    # One detection in 2.5 s shows no gap, yet 74 of the camera's 75 frames never came back.
    assert cp.count_missed([1.0], 30, 2.5) == 74


@pytest.mark.slow
def test_perception_fix_improves_delivered_rate(rt):
    cp.start_robot(rt, "robot1")
    timing = "/robot1/perception/processing_time_ms"

    def measure(detector: str, depth: int):
        rt.spawn("perception", cp.Perception, params={"namespace": "/robot1", "detector": detector,
                                                      "depth": depth}, wait_for="/robot1/perception")
        return cp.measure_delivery(rt, "/robot1/perception/detections", seconds=2.0, timing_topic=timing)

    def improved(pair) -> bool:
        broken, fixed = pair
        return (fixed.delivered_hz > 1.5 * broken.delivered_hz
                and fixed.missed_fraction < broken.missed_fraction
                and broken.mean_callback_ms > 1000 / 30 > 3 * fixed.mean_callback_ms
                # the newest frame when a callback ends is at most a period old: gaps >= callback - 1 period
                and broken.median_gap_frames > broken.median_callback_ms * 30 / 1000 - 1.25)

    broken, fixed = assert_timing("the numpy detector delivers more, misses less, and fits the frame period",
                                  lambda: (measure("python", 1), measure("numpy", 5)), improved)
    # perception's own stopwatch, read in the same windows: one time per detection (give or take the
    # window's edges)
    for delivery in (broken, fixed):
        assert abs(len(delivery.callback_ms) - delivery.received) <= 2, delivery
    frame = cp.make_frame(5).tobytes()
    assert cp.detect_marker_numpy(frame, 160, 120) == cp.detect_marker_python(frame, 160, 120)


def test_bad_capstone_input_names_what_is_allowed(rt, robot):
    _handle, runner, _button = robot
    with pytest.raises(CourseError, match="shelves: A1, A2, B1, B2"):
        runner.start("x", shelf="Z9")
    with pytest.raises(CourseError, match="detector must be one of"):
        rt.add(cp.Perception, "/robot1", detector="magic")


# ---------------------------------------------------------------------------------- the exercise
FLEET_ESTOP = "/fleet/estop"


class MissingQos(cp.SafetyMonitor):
    """Forgets the QoS argument: the constructor raises."""

    def __init__(self, namespace="/robot1"):
        super().__init__(namespace)
        self.fleet = self.create_subscription(EStop, FLEET_ESTOP, self.on_fleet_estop)

    def on_fleet_estop(self, msg):
        pass


class RenamedMonitor(FleetSafetyMonitor):
    """A monitor under a name of its own: the operator's button calls safety_monitor/engage."""

    def __init__(self, namespace="/robot1"):
        Node.__init__(self, "fleet_monitor", namespace=namespace)


class StartsEngaged(FleetSafetyMonitor):
    """Treats 'no fleet message yet' as a fleet stop: the robot never moves without a fleet manager."""

    def __init__(self, namespace="/robot1"):
        super().__init__(namespace)
        self.publish_estop(True, "fleet state unknown", "fleet")


class RelativeTopic(FleetSafetyMonitor):
    """Subscribes to 'fleet/estop', which resolves to /robot4/fleet/estop: it never hears the fleet."""

    def __init__(self, namespace="/robot1"):
        cp.SafetyMonitor.__init__(self, namespace)
        self.fleet_stopped = False
        self.fleet_subscription = self.create_subscription(EStop, "fleet/estop", self.on_fleet_estop,
                                                           ESTOP_QOS)


class VolatileSubscription(FleetSafetyMonitor):
    """The default QoS (VOLATILE): a monitor that starts after the fleet stop never hears it."""

    def __init__(self, namespace="/robot1"):
        cp.SafetyMonitor.__init__(self, namespace)
        self.fleet_stopped = False
        self.fleet_subscription = self.create_subscription(EStop, FLEET_ESTOP, self.on_fleet_estop, 10)


class OperatorMayRelease(FleetSafetyMonitor):
    """Leaves the operator's service as it was: a release during the fleet stop goes through."""

    def on_engage(self, request, response):
        return cp.SafetyMonitor.on_engage(self, request, response)


class IgnoresFleetRelease(FleetSafetyMonitor):
    """Engages on a fleet stop, but never releases when the fleet does."""

    def on_fleet_estop(self, msg):
        self.fleet_stopped = msg.engaged
        if msg.engaged and not self.current.engaged:
            self.publish_estop(True, f"fleet stop: {msg.reason}", "fleet")


class FollowsEveryFleetRelease(FleetSafetyMonitor):
    """Copies the fleet's state, also releasing an e-stop that the robot's own operator pressed."""

    def on_fleet_estop(self, msg):
        self.fleet_stopped = msg.engaged
        if msg.engaged != self.current.engaged:
            self.publish_estop(msg.engaged, f"fleet: {msg.reason}", "fleet")


CRITERIA = [
    "your safety monitor runs in a robot's namespace",
    "with no fleet stop, the robot starts released",
    "a fleet stop engages the robot's e-stop and stops its mission",
    "a robot whose safety monitor starts after the fleet stop is stopped too",
    "while the fleet stop holds, the robot's operator cannot release it",
    "the fleet's release lets every robot it stopped drive again",
    "a fleet release leaves the operator's own e-stop engaged, until the operator releases it",
]


def test_the_fleet_checker_passes_the_reference_and_cleans_up(rt):
    report = check_fleet_estop(FleetSafetyMonitor)
    assert report.passed, report.summary()
    assert [c.name for c in report.criteria] == CRITERIA
    assert_reference_criteria("check_fleet_estop", report)
    assert rt.nodes() == [] and sorted(rt.children()) == []  # robots 4 and 5 are gone again
    assert not any(n.startswith(("/robot4", "/robot5")) for n in rt.graph_nodes())


MISTAKES = [  # one plausible wrong monitor per criterion, and the criterion it must fail
    (MissingQos, CRITERIA[0]),
    (RenamedMonitor, CRITERIA[0]),
    (StartsEngaged, CRITERIA[1]),
    (RelativeTopic, CRITERIA[2]),
    (VolatileSubscription, CRITERIA[3]),
    (OperatorMayRelease, CRITERIA[4]),
    (IgnoresFleetRelease, CRITERIA[5]),
    (FollowsEveryFleetRelease, CRITERIA[6]),
]



@pytest.mark.parametrize("wrong, criterion", MISTAKES, ids=[wrong.__name__ for wrong, _ in MISTAKES])
def test_the_fleet_checker_fails_each_criterion_on_a_plausible_mistake(rt, wrong, criterion):
    report = check_fleet_estop(wrong)
    failed = [c.name for c in report.criteria if not c.passed]
    assert failed and failed[-1] == criterion, report.summary()
    assert not report.passed
    hint = next(c.hint for c in report.criteria if c.name == criterion and not c.passed)
    assert hint  # a failed criterion says where to look
    assert rt.nodes() == [] and sorted(rt.children()) == []


class SlowStampedSource(Node):
    """Publishes a stamped point every 0.6 s: a window of 1 s holds at most two of them."""

    def __init__(self):
        super().__init__("slow_stamped_source")
        self.publisher = self.create_publisher(PointStamped, "slow_stamped", 10)
        self.timer = self.create_timer(0.6, self.tick)

    def tick(self):
        msg = PointStamped()
        msg.header.stamp = self.get_clock().now().to_msg()
        self.publisher.publish(msg)


def test_a_window_goes_on_until_it_holds_gaps_to_measure(rt):
    rt.add(SlowStampedSource)
    delivery = cp.measure_delivery(rt, "/slow_stamped", seconds=1.0, expected_hz=30.0)
    assert delivery.received >= 3 and len(delivery.gap_frames) >= 2, delivery  # two gaps, not none
    assert delivery.seconds >= 1.0  # the window is never shorter than asked for
    assert_timing("a 0.6 s source shows gaps of about 18 frames of a 30 Hz camera",
                  lambda: cp.measure_delivery(rt, "/slow_stamped", seconds=1.0, expected_hz=30.0),
                  lambda d: 0.6 * 30 * 0.8 < d.median_gap_frames < 0.6 * 30 * 1.25)


COVERED = {"check_fleet_estop": {criterion for _wrong, criterion in MISTAKES}}
