"""Chapter 06's launch exercise (every checker criterion fails on a wrong solution), its launch file, and the
rate tuner's record, with real nodes in child processes."""

from __future__ import annotations

import ast

import pytest
from rclpy.parameter import Parameter

from course_helpers import CourseError
from course_helpers.chapters.ch06_parameters import NodeLaunch, RateTalker, RateTuner, launch_file
from course_helpers.checks.ch06_parameters import check_conveyor_launch
from course_helpers.core.verdict import reusing
from course_helpers.solutions.ch06_parameters import conveyor_launch, conveyor_talks
from tests.timing import assert_timing

from .criteria_registry import assert_reference_criteria, failing


def _failed(report) -> set[str]:
    return {c.name for c in report.criteria if not c.passed}


def _describe_with_a_typo():
    """Wrong: the counter listens on 'item', one letter short of the sensor's 'items'."""
    talker, _counter = conveyor_launch()
    return [talker, NodeLaunch("listener", "counter", "/line1", {"topic": "item", "log_every": 5})]


def _describe_with_an_integer_rate():
    """Wrong: rate_hz=10, an integer for a double parameter: the sensor's process refuses to start."""
    talker, counter = conveyor_launch()
    return [NodeLaunch("talker", "belt_sensor", "/line1", {**talker.parameters, "rate_hz": 10}), counter]


def _describe_with_a_misspelt_argument():
    """Wrong: NodeLaunch has no 'node_name' argument; building the description raises."""
    return [NodeLaunch("talker", node_name="belt_sensor")]


def _proof_that_does_not_look(_rt):
    """Wrong: says yes without looking."""
    return True


# (describe, proof, the criteria that must fail); the description cases start nothing
CONVEYOR_WRONG = [
    pytest.param(_describe_with_a_misspelt_argument, conveyor_talks,
                 {"conveyor_launch() returns the launch description"}, id="describe-raises"),
    pytest.param(lambda: [], conveyor_talks, {"it describes two nodes as NodeLaunch entries"}, id="empty"),
    pytest.param(lambda: [NodeLaunch("talker", "belt_sensor"), NodeLaunch("listener", "counter")],
                 conveyor_talks, {"the nodes are /line1/belt_sensor (talker) and /line1/counter (listener)"},
                 id="no-namespace"),
    pytest.param(conveyor_launch, _proof_that_does_not_look,
                 {"your proof says no when the counter listens on another topic (/line1/items_v2)"},
                 id="proof-does-not-look"),
    pytest.param(_describe_with_an_integer_rate, conveyor_talks, {"the two nodes start together"},
                 id="integer-rate"),
    pytest.param(_describe_with_a_typo, conveyor_talks,
                 {"the nodes run with the parameters asked for",
                  "the counter hears the belt sensor (its process says so)",
                  "your proof says yes for your running nodes"},  # the reference proof is honest
                 id="topic-typo"),
]


def test_conveyor_checker_accepts_the_reference_and_leaves_nothing_running(rt):
    report = check_conveyor_launch(conveyor_launch, conveyor_talks, rt=rt)
    print(report)
    assert report.passed, report.summary()
    assert_reference_criteria("check_conveyor_launch", report)
    assert not [name for name in rt.children() if name.startswith(("ex06_conveyor__", "ex06_miswired__"))]


@pytest.mark.parametrize("describe, proof, failing", CONVEYOR_WRONG)
def test_conveyor_checker_fails_each_criterion_on_a_wrong_solution(rt, describe, proof, failing):
    report = check_conveyor_launch(describe, proof, rt=rt)
    print(report)
    assert not report.passed
    assert failing <= _failed(report), report.summary()
    assert not [name for name in rt.children() if name.startswith(("ex06_conveyor__", "ex06_miswired__"))]


def test_conveyor_checker_stops_at_a_wrong_description_before_starting_anything(rt):
    unnamespaced = [NodeLaunch("talker", "belt_sensor"), NodeLaunch("listener", "counter")]
    report = check_conveyor_launch(lambda: unnamespaced, conveyor_talks, rt=rt)
    assert _failed(report) == {"the nodes are /line1/belt_sensor (talker) and /line1/counter (listener)"}
    assert not rt.children()
    hints = " ".join(c.hint for c in report.criteria)
    assert "belt_sensor" not in hints and "NodeLaunch(" not in hints, "hints point to the text"


def test_launch_file_is_the_real_launch_description_of_the_entries():
    text = launch_file([NodeLaunch("talker", "talker", namespace="robot2", params_file="config/robots.yaml",
                                   parameters={"rate_hz": 5.0}),
                        NodeLaunch("listener", "counter", namespace="/line1")], package="conveyor")
    tree = ast.parse(text)
    imports = {(node.module, alias.name) for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
               for alias in node.names}
    assert imports == {("launch", "LaunchDescription"), ("launch_ros.actions", "Node")}
    [function] = [node for node in tree.body if isinstance(node, ast.FunctionDef)]
    assert function.name == "generate_launch_description"
    calls = [node for node in ast.walk(function) if isinstance(node, ast.Call) and node.func.id == "Node"]
    nodes = [{k.arg: ast.literal_eval(k.value) for k in call.keywords} for call in calls]
    assert nodes == [
        {"package": "conveyor", "executable": "talker", "name": "talker", "namespace": "/robot2",
         "parameters": ["config/robots.yaml", {"rate_hz": 5.0}]},
        {"package": "conveyor", "executable": "listener", "name": "counter", "namespace": "/line1"},
    ]
    assert "Node(" not in launch_file([]).split("LaunchDescription([")[1]
    with pytest.raises(CourseError, match="kind must be one of"):
        launch_file([NodeLaunch("camera", "front")])


@pytest.mark.timing
def test_rate_tuner_record_shows_the_rate_set_and_the_rate_measured_for_it(rt):
    rt.add(RateTalker, "talker", parameter_overrides=[Parameter("rate_hz", value=4.0)])
    tuner = RateTuner("/talker", "chatter", rt=rt)
    tuner.widget()
    updates = []

    class KeptRecord:  # stands in for the notebook's Record outside a kernel: keeps each update
        def update(self, text, html_body=None, figure=None):
            updates.append((text, html_body, figure))

    tuner.record = KeptRecord()
    assert tuner.set_rate(10.0).successful
    assert tuner._widgets[0].value == 10.0  # the slider follows a rate set from code
    measured = tuner.measure(1.0)
    assert not tuner.set_rate(500.0).successful
    tuner.update_record()
    text, body, figure = updates[-1]
    assert "rate_hz set to 10.0 Hz" in text and f"measured on chatter: {measured:.1f} Hz" in text
    assert "last refused: 500 Hz" in text and "10.0 Hz" in body
    assert figure is not None and len(figure.axes) == 1
    assert tuner._widgets[0].value == 10.0  # a refused rate leaves the slider where the node is
    assert_timing("the talker set to 10 Hz publishes at 7 to 13 Hz",
                  reusing(measured, lambda: tuner.measure(1.0)), lambda hz: 7.0 < hz < 13.0,
                  show=lambda hz: f"{hz:.1f} Hz")


def test_rate_tuner_record_says_not_measured_yet_after_a_new_setting(rt):
    hz = 5.0
    rt.add(RateTalker, "talker", parameter_overrides=[Parameter("rate_hz", value=4.0)])
    tuner = RateTuner("/talker", "chatter", rt=rt)
    tuner.measure(0.5, settle_s=0.0)
    tuner.set_rate(hz)
    text, _body = tuner._record_body()
    assert f"set to {hz:.1f} Hz" in text and f"not measured yet at {hz:.1f} Hz" in text


COVERED = {"check_conveyor_launch": failing(CONVEYOR_WRONG, 2)}
ONLY_WHEN_FAILING = {"check_conveyor_launch": {"conveyor_launch() returns the launch description",
                                              "the checker's miswired pair starts"}}
EXEMPT = {"check_conveyor_launch": {
    "the checker's miswired pair starts": "the checker's own two nodes, launched before the student's proof "
                                          "runs: nothing the student writes reaches them",
}}
