"""Chapter 06's launch exercise and the rate tuner's record, with real nodes in child processes."""

from __future__ import annotations

from rclpy.parameter import Parameter

from course_helpers.chapters.ch06_parameters import NodeLaunch, RateTalker, RateTuner
from course_helpers.checks.ch06_parameters import check_conveyor_launch
from course_helpers.solutions.ch06_parameters import conveyor_launch, conveyor_talks


def _failed(report) -> list[str]:
    return [c.name for c in report.criteria if not c.passed]


def test_conveyor_checker_accepts_the_reference_and_leaves_nothing_running(rt):
    report = check_conveyor_launch(conveyor_launch, conveyor_talks, rt=rt)
    print(report)
    assert report.passed, report.summary()
    assert len(report.criteria) == 7
    assert not [name for name in rt.children() if name.startswith(("ex06_conveyor__", "ex06_miswired__"))]


def test_conveyor_checker_rejects_a_listener_on_the_wrong_topic(rt):
    def typo_launch():
        talker, counter = conveyor_launch()
        return [talker, NodeLaunch("listener", "counter", "/line1", {"topic": "item", "log_every": 5})]

    report = check_conveyor_launch(typo_launch, conveyor_talks, rt=rt)
    print(report)
    assert not report.passed
    assert "the nodes run with the parameters asked for" in _failed(report)
    assert "the counter hears the belt sensor (its process says so)" in _failed(report)
    assert "your proof says yes for your running nodes" in _failed(report)  # the reference proof is honest


def test_conveyor_checker_rejects_a_proof_that_does_not_look(rt):
    report = check_conveyor_launch(conveyor_launch, lambda _rt: True, rt=rt)
    print(report)
    assert _failed(report) == [
        "your proof says no when the counter listens on another topic (/line1/items_v2)"]


def test_conveyor_checker_explains_a_description_that_is_not_one(rt):
    report = check_conveyor_launch(lambda: [], conveyor_talks, rt=rt)
    assert _failed(report) == ["it describes two nodes as NodeLaunch entries"]
    unnamespaced = [NodeLaunch("talker", "belt_sensor"), NodeLaunch("listener", "counter")]
    report = check_conveyor_launch(lambda: unnamespaced, conveyor_talks, rt=rt)
    assert _failed(report) == ["the nodes are /line1/belt_sensor (talker) and /line1/counter (listener)"]
    assert not rt.children()  # nothing starts before the description is right


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
    assert 7.0 < measured < 13.0


def test_rate_tuner_record_says_not_measured_yet_after_a_new_setting(rt):
    hz = 5.0
    rt.add(RateTalker, "talker", parameter_overrides=[Parameter("rate_hz", value=4.0)])
    tuner = RateTuner("/talker", "chatter", rt=rt)
    tuner.measure(0.5, settle_s=0.0)
    tuner.set_rate(hz)
    text, _body = tuner._record_body()
    assert f"set to {hz:.1f} Hz" in text and f"not measured yet at {hz:.1f} Hz" in text
