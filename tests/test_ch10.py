"""Chapter 10 (capstone), with real nodes and processes."""

from __future__ import annotations

import copy

import pytest
from course_interfaces.msg import EStop
from course_interfaces.srv import PickItem
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from std_srvs.srv import Trigger

from course_helpers import CourseError, WaitTimeout
from course_helpers.chapters import ch10_capstone as cp
from course_helpers.checks.ch10_capstone import check_design, incompatibility
from course_helpers.core.domains import nodes_in_domain, reserve_spare_domain
from course_helpers.solutions.ch10_capstone import REFERENCE_DESIGN


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


def test_design_checker_accepts_reference_and_rejects_broken(rt):
    cp.start_robot(rt, "robot1")  # with its camera: the design declares it
    rt.add(cp.MissionRunner, "/robot1", console=False)
    report = check_design(REFERENCE_DESIGN)
    assert report.passed, report.summary()

    broken = copy.deepcopy(REFERENCE_DESIGN)
    estop = next(t for t in broken["topics"] if t["name"] == "estop")
    estop["qos"] = {"reliability": "reliable", "durability": "volatile", "depth": 10}
    report = check_design(broken)
    assert not report.passed
    failed = {c.name for c in report.criteria if not c.passed}
    assert "the e-stop is RELIABLE + TRANSIENT_LOCAL on both sides" in failed
    assert "a late joiner with your e-stop QoS learns the current e-stop state" in failed
    assert "the declared QoS is compatible with the endpoints that run" in failed

    wrong_endpoints = copy.deepcopy(REFERENCE_DESIGN)
    wrong_endpoints["services"][0]["server"] = "navigator"
    wrong_endpoints["services"][0]["clients"] = ["no_such_node"]
    wrong_endpoints["actions"] = []
    wrong_endpoints["nodes"].append("perception")
    failed = {c.name for c in check_design(wrong_endpoints).criteria if not c.passed}
    assert {"every declared node runs under /robot1",
            "the design covers every channel the robot needs",
            "every declared service exists with its server and clients"} <= failed

    strangers = copy.deepcopy(REFERENCE_DESIGN)
    strangers["actions"][0]["clients"] = ["no_such_node"]
    strangers["services"][0]["clients"] = ["not a name!"]
    failed = {c.name for c in check_design(strangers).criteria if not c.passed}
    assert failed == {"every declared service exists with its server and clients",
                      "every declared action exists with its server and clients"}

    assert not check_design("not a design").passed
    assert not check_design({"topics": [{"name": "x", "type": "no/such/Type"}]}).passed


def test_missed_frames_count_gaps_and_a_shortfall():
    period = 1 / 30
    every_frame = [i * period for i in range(75)]
    assert cp.count_missed(every_frame, 30, 2.5) == 0
    every_third = every_frame[::3]  # 25 of 75 frames: two lost in each gap, and two after the last
    assert cp.count_missed(every_third, 30, 2.5) == 50
    assert cp.count_missed(every_third, 30, 2.5 - 2 * period) == 2 * (len(every_third) - 1)
    # One detection in 2.5 s shows no gap, yet 74 of the camera's 75 frames never came back.
    assert cp.count_missed([1.0], 30, 2.5) == 74


def test_qos_compatibility_rule():
    assert incompatibility(("best_effort", "volatile"), ("reliable", "volatile"))
    assert incompatibility(("reliable", "volatile"), ("reliable", "transient_local"))
    assert not incompatibility(("reliable", "transient_local"), ("best_effort", "volatile"))


@pytest.mark.slow
def test_perception_fix_improves_delivered_rate(rt):
    cp.start_robot(rt, "robot1")
    rt.spawn("perception", cp.Perception, params={"namespace": "/robot1", "detector": "python", "depth": 1},
             wait_for="/robot1/perception")
    broken = cp.measure_delivery(rt, "/robot1/perception/detections", seconds=2.0)
    rt.spawn("perception", cp.Perception, params={"namespace": "/robot1", "detector": "numpy", "depth": 5},
             wait_for="/robot1/perception")
    fixed = cp.measure_delivery(rt, "/robot1/perception/detections", seconds=2.0)
    assert fixed.delivered_hz > 1.5 * broken.delivered_hz, (broken, fixed)
    assert fixed.missed_fraction < broken.missed_fraction
    frame = cp.make_frame(5).tobytes()
    assert cp.detect_marker_numpy(frame, 160, 120) == cp.detect_marker_python(frame, 160, 120)


def test_bad_capstone_input_names_what_is_allowed(rt, robot):
    _handle, runner, _button = robot
    with pytest.raises(CourseError, match="shelves: A1, A2, B1, B2"):
        runner.start("x", shelf="Z9")
    with pytest.raises(CourseError, match="detector must be one of"):
        rt.add(cp.Perception, "/robot1", detector="magic")
