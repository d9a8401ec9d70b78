"""Every criterion of the checkers of chapters 00, 01 and 07 fails on one plausible wrong input.

Chapter 00's check judges the environment: its criteria are fed facts with one thing wrong, and the
whole check runs in fresh processes whose environment really is wrong (discovery open to the network,
a context shut down, a package that cannot be imported). Chapter 07's checker runs real nodes over
real Fast DDS: each wrong solution is a mistake a student makes, and the test names the criterion
that must catch it. Chapter 01's wrong watchdogs live beside its other checker tests, in
``test_ch01_04_exercises.py`` (a file of its own lets ``make test`` run them in parallel with these).
"""

from __future__ import annotations

import dataclasses
import json
import os

import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions, get_current_signal_handlers_options, uninstall_signal_handlers
from std_msgs.msg import Int32, String

from course_helpers.checks.ch00_environment import environment_report, observe_environment
from course_helpers.checks.ch07_dds import check_private_robot
from course_helpers.notebook import interrupts
from course_helpers.solutions.ch07_dds import PrivateRobot, private_context

from .conftest import run_python
from .criteria_registry import assert_reference_criteria, failing, recorded_names_starting_with


@pytest.fixture(autouse=True)
def _rclpys_handlers_off():
    """Each test starts as every cell of a course kernel does: without rclpy's signal handlers
    (notebook/interrupts.install removes any a textbook rclpy.init() left). In a test process another
    test may have left them installed, and 07.1's checker judges a change from the state it found."""
    if get_current_signal_handlers_options() != SignalHandlerOptions.NO:
        uninstall_signal_handlers()


def _failed(report) -> list[str]:
    return [c.name for c in report.criteria if not c.passed]


def _criterion(report, start: str):
    found = [c for c in report.criteria if c.name.startswith(start)]
    assert len(found) == 1, (start, report.summary())
    return found[0]


# ---------------------------------------------------------------------- 00: the environment check
# The start of each criterion's name (some hold a version), and the one fact that is wrong for it.
WRONG_FACTS = {
    "Python is a supported version": {"python": (3, 9)},
    "rclpy ": {"context_running": False},
    "middleware is rmw_fastrtps_cpp": {"rmw": "rmw_cyclonedds_cpp"},
    "message packages": {"missing_messages": ["sensor_msgs.msg"]},
    "the course's own interfaces": {"interfaces_built": False},
    "this kernel has its own ROS domain": {"domain_chosen_by": "user"},
    "discovery stays on this machine": {"udp_sockets": [("0.0.0.0", 7400)]},  # added to the real ones
}


def test_each_environment_criterion_fails_on_facts_with_one_thing_wrong(rt):
    facts = observe_environment(rt)
    for start, fault in WRONG_FACTS.items():
        if "udp_sockets" in fault:
            fault = {"udp_sockets": facts.udp_sockets + fault["udp_sockets"]}
        facts_with_a_fault = dataclasses.replace(facts, **fault)
        assert not _criterion(environment_report(facts_with_a_fault), start).passed, start
    # The real facts: everything that does not depend on the test run. Not discovery: this worker's
    # UDP sockets include those of participants other test files left in it (a test worker is no
    # fresh kernel); test_discovery_criterion_passes_the_course_kernel_... checks it in a new process.
    report = environment_report(facts)
    for start in ("Python", "rclpy ", "middleware", "message packages", "the course's own"):
        assert _criterion(report, start).passed, report.summary()


def test_a_kernel_without_any_socket_has_no_participant_to_call_local(rt):
    facts = dataclasses.replace(observe_environment(rt), udp_sockets=[])
    criterion = _criterion(environment_report(facts), "discovery stays on this machine")
    assert not criterion.passed and "no DDS participant" in criterion.detail


def _check_in_fresh_process(prologue: str = "", env: dict | None = None, epilogue: str = "") -> dict:
    """Chapter 00's check in a new Python: passed, by criterion."""
    out = run_python(f"""
        import json, os, sys
        {prologue}
        from course_helpers import get_runtime
        from course_helpers.checks.ch00_environment import check_environment
        rt = get_runtime()
        {epilogue}
        report = check_environment(rt)
        print(json.dumps({{c.name: [c.passed, c.detail] for c in report.criteria}}))
        rt.stop()
    """, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def _discovery(criteria: dict) -> list:
    return next(v for k, v in criteria.items() if k.startswith("discovery stays on this machine"))


def test_discovery_criterion_passes_the_course_kernel_and_fails_one_open_to_the_network():
    local = _check_in_fresh_process()  # a fresh kernel is the environment check's reference solution
    assert all(passed for passed, _detail in local.values()), local
    assert_reference_criteria("check_environment", local)
    subnet = _check_in_fresh_process(env={"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"})
    passed, detail = _discovery(subnet)
    assert not passed and "0.0.0.0:" in detail, subnet


def test_discovery_criterion_reads_the_sockets_not_the_variable():
    """The kernel starts open to the network; the variable says LOCALHOST again before the check."""
    criteria = _check_in_fresh_process(env={"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"},
                                       epilogue="os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'")
    passed, detail = _discovery(criteria)
    assert not passed and "open to the network" in detail, criteria


def test_context_criterion_fails_when_ros_was_shut_down_from_outside():
    criteria = _check_in_fresh_process(epilogue="rt.context.shutdown()")
    passed, detail = next(v for k, v in criteria.items() if k.startswith("rclpy "))
    assert not passed and "not running" in detail, criteria


def test_package_criteria_fail_when_a_package_cannot_be_imported():
    criteria = _check_in_fresh_process(prologue="sys.modules['test_msgs'] = None; "
                                                "sys.modules['course_interfaces'] = None")
    passed, detail = criteria["message packages std_msgs, std_srvs, geometry_msgs, sensor_msgs, test_msgs"]
    assert not passed and detail == "missing: test_msgs.action", criteria
    assert criteria["the course's own interfaces (course_interfaces) are built"] == [False, ""], criteria


# ---------------------------------------------------------------------- 07: a robot the class cannot see
def context_via_the_environment(domain_id):
    """Wrong: sets ROS_DOMAIN_ID in the kernel's environment, which its later children inherit."""
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    context = Context()
    context.init()
    return context


def context_with_signal_handlers(domain_id):
    """Wrong: initialises rclpy's default context, which installs rclpy's signal handlers too (the
    interrupt button would then stop ROS)."""
    rclpy.init(domain_id=domain_id)
    return rclpy.get_default_context()


def context_asking_for_handlers(domain_id):
    """Wrong: a context of its own, but asks rclpy.init for its signal handlers."""
    context = Context()
    rclpy.init(context=context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.ALL)
    return context


def context_through_rclpy_init(domain_id):
    """Right: rclpy.init on a context of its own (rclpy installs no handler for it unless asked)."""
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    return context


def context_in_the_default_domain(domain_id):
    """Wrong: forgets the domain, so the context joins the kernel's (the class's)."""
    context = Context()
    context.init()
    return context


def context_that_raises(domain_id):
    """Wrong: passes the domain where the arguments go."""
    context = Context()
    context.init([domain_id])
    return context


def the_domain_number(domain_id):
    """Wrong: returns the domain instead of a context."""
    return domain_id


class IgnoresItsContext(PrivateRobot):
    """Wrong: does not pass the context on, so the node joins rclpy's default context."""

    def __init__(self, context=None):
        Node.__init__(self, "private_robot")
        self.publisher = self.create_publisher(String, "robot_status", 10)
        self.timer = self.create_timer(0.2, self.tick)


class OtherName(PrivateRobot):
    """Wrong: named after the team, not private_robot."""

    def __init__(self, context=None):
        Node.__init__(self, "team_robot", context=context)
        self.publisher = self.create_publisher(String, "robot_status", 10)
        self.timer = self.create_timer(0.2, self.tick)


class StatusAsNumber(Node):
    """Wrong: publishes an Int32 on robot_status."""

    def __init__(self, context=None):
        super().__init__("private_robot", context=context)
        self.publisher = self.create_publisher(Int32, "robot_status", 10)
        self.timer = self.create_timer(0.2, lambda: self.publisher.publish(Int32(data=1)))


class NeverPublishes(PrivateRobot):
    """Wrong: creates the publisher and no timer, so nothing is ever sent."""

    def __init__(self, context=None):
        Node.__init__(self, "private_robot", context=context)
        self.publisher = self.create_publisher(String, "robot_status", 10)


class TalksTooOften(PrivateRobot):
    """Wrong: a period of 0.02 s (50 times a second) instead of 0.2 s."""

    def __init__(self, context=None):
        super().__init__(context=context)
        self.destroy_timer(self.timer)
        self.timer = self.create_timer(0.02, self.tick)


class BrokenTick(PrivateRobot):
    """Wrong: publishes a str instead of a String message (the timer callback raises TypeError)."""

    def tick(self):
        self.publisher.publish("ok")


class NotWrittenYet(Node):
    """Unfinished: TODO 2 and 3 left (the constructor raises), so the checker stops after the context."""

    def __init__(self, context=None):
        raise NotImplementedError("TODO 2")


CONTEXT = "private_context(domain_id) returns an initialised Context in that domain"
TEAM_HEARS = "its team hears it: a listener process in its domain receives its status"
CLASS_BLIND = "the class cannot see it: its domain is not the class's"
RATE = "it publishes its status five times a second"


HANDLERS_OFF = "rclpy's signal handlers stay off"
BUILDS_IN_CONTEXT = "PrivateRobot(context=...) builds its node in that context"
ROBOT_WRONG = [
    pytest.param(PrivateRobot, context_that_raises, {"private_context(domain_id) runs"}, id="raises"),
    pytest.param(PrivateRobot, context_via_the_environment, {"the kernel's environment is left as it was"},
                 id="environment"),
    pytest.param(NotWrittenYet, context_with_signal_handlers, {HANDLERS_OFF}, id="default-context"),
    pytest.param(NotWrittenYet, context_asking_for_handlers, {HANDLERS_OFF}, id="asks-for-handlers"),
    pytest.param(PrivateRobot, the_domain_number, {CONTEXT}, id="a-number"),
    pytest.param(PrivateRobot, context_in_the_default_domain, {CONTEXT, TEAM_HEARS, CLASS_BLIND},
                 id="default-domain"),
    pytest.param(IgnoresItsContext, private_context, {BUILDS_IN_CONTEXT}, id="ignores-context"),
    pytest.param(OtherName, private_context, {"the node is named private_robot"}, id="name"),
    pytest.param(StatusAsNumber, private_context, {"it publishes std_msgs/msg/String on /robot_status",
                                                   TEAM_HEARS}, id="int32"),
    pytest.param(NeverPublishes, private_context, {RATE, TEAM_HEARS}, id="never-publishes"),
    pytest.param(TalksTooOften, private_context, {RATE}, id="too-often"),
    pytest.param(BrokenTick, private_context, {"callbacks raised no errors"}, id="callback-raises"),
]


@pytest.mark.parametrize("robot, make_context, criteria", ROBOT_WRONG)
def test_private_robot_checker_rejects(rt, robot, make_context, criteria):
    environment = dict(os.environ)
    report = check_private_robot(robot, make_context, rt)
    assert criteria <= set(_failed(report)), report.summary()
    assert dict(os.environ) == environment  # the checker put back what the wrong solution changed
    assert get_current_signal_handlers_options() == SignalHandlerOptions.NO
    assert "team_listener" not in rt.children()


def test_the_signal_criterion_is_the_student_s_even_where_rclpy_init_is_the_course_s(rt, monkeypatch):
    """In a course kernel rclpy.init() installs no handler unless asked (notebook/interrupts.py), so a
    textbook rclpy.init() on the default context would pass there. The checker runs private_context
    with rclpy's own choice: the wrapper is installed here as a kernel installs it, and the textbook
    call fails, whether it goes through rclpy.init or a name bound before (from rclpy import init)."""
    course_init = interrupts._course_init(rclpy.init)
    monkeypatch.setattr(rclpy, "init", course_init)

    def context_with_a_bound_init(domain_id):
        course_init(domain_id=domain_id)
        return rclpy.get_default_context()

    for wrong in (context_with_signal_handlers, context_with_a_bound_init, context_asking_for_handlers):
        report = check_private_robot(NotWrittenYet, wrong, rt)
        assert HANDLERS_OFF in _failed(report), (wrong.__name__, report.summary())
        assert get_current_signal_handlers_options() == SignalHandlerOptions.NO
    report = check_private_robot(NotWrittenYet, context_through_rclpy_init, rt)
    assert _failed(report) == [BUILDS_IN_CONTEXT], report.summary()
    # outside the checker, the course's rclpy.init still installs nothing
    context = Context()
    course_init(context=context, domain_id=0, args=[])
    try:
        assert get_current_signal_handlers_options() == SignalHandlerOptions.NO
    finally:
        context.try_shutdown()


def test_private_robot_checker_accepts_the_reference_and_leaves_nothing_behind(rt):
    report = check_private_robot(PrivateRobot, private_context, rt)
    assert report.passed, report.summary()
    assert_reference_criteria("check_private_robot", report)
    assert "/private_robot" not in rt.graph_nodes() and "team_listener" not in rt.children()


COVERED = {
    "check_environment": recorded_names_starting_with("check_environment", WRONG_FACTS),
    "check_private_robot": failing(ROBOT_WRONG, 2),
}
ONLY_WHEN_FAILING = {"check_private_robot": {"private_context(domain_id) runs"}}
