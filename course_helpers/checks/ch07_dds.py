"""Checker of chapter 07's exercise: a robot that its team hears and the class cannot see.

The student writes ``private_context(domain_id)``, a new rclpy context whose participant joins ROS
domain ``domain_id``, and ``PrivateRobot(context=...)``, a node named ``private_robot`` that publishes
a ``std_msgs/String`` on ``robot_status`` five times a second. The checker hands them the spare
domain reserved for this kernel. It counts the robot's messages over 1 s of a clock it owns (exact
on any machine), checks that the robot's domain is not the class's (this kernel's, which stands for
the domain the class shares: participants of different domains never discover each other), and then
that its team hears it: a listener process in that domain receives its status. It also checks that
the kernel is left as it was: the environment its children inherit, and rclpy's signal handlers
switched off. For that last one the checker calls ``private_context`` with ``rclpy.init`` choosing
the signal handlers as rclpy itself does
(:func:`~course_helpers.notebook.interrupts.rclpys_own_signal_default`): a course kernel's
``rclpy.init`` installs none unless asked, so without this the criterion could not fail there,
whatever the student wrote. What is judged is the student's code: a function that initialises
rclpy's default context gets rclpy's handlers, one that initialises a context of its own gets none,
unless it asks for them.
"""

from __future__ import annotations

import os

from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions, get_current_signal_handlers_options, uninstall_signal_handlers
from rclpy.utilities import get_default_context, try_shutdown

from course_helpers.chapters.ch07_dds import ReportingListener, heard_lines
from course_helpers.checks import CheckReport
from course_helpers.core.domains import reserve_spare_domain
from course_helpers.core.executors import SingleThreaded, SpinThread
from course_helpers.core.sim_clock import SimClock
from course_helpers.core.waiting import poll_until
from course_helpers.notebook.interrupts import rclpys_own_signal_default

ROBOT_NAME = "private_robot"
STATUS_TOPIC = "/robot_status"
STATUS_TYPE = "std_msgs/msg/String"
TEAM_LISTENER = "team_listener"  # the probe process in the team's domain (label and node name)
HEARD_MESSAGES = 3  # the team must hear at least this many status messages
HANG_S = 60.0  # bounds a hang only: a listener process starts, discovers and hears within seconds
STATUS_HZ = 5.0  # the exercise's rate
RATE_WINDOW_S = 1.0  # [s of the checker's clock] the rate is counted over this long
RATE = "it publishes its status five times a second"
TEAM_HEARS = "its team hears it: a listener process in its domain receives its status"
ENVIRONMENT_PREFIXES = ("ROS_", "RMW_", "FASTRTPS_", "FASTDDS_")  # what children inherit and rcl reads


def _ros_environment() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k.startswith(ENVIRONMENT_PREFIXES)}


def _restore_environment(saved: dict[str, str]) -> list[str]:
    """Put the ROS variables of ``os.environ`` back as ``saved``; return the names that had changed."""
    changed = sorted(k for k in set(saved) | set(_ros_environment()) if os.environ.get(k) != saved.get(k))
    for key in changed:
        if key in saved:
            os.environ[key] = saved[key]
        else:
            os.environ.pop(key, None)
    return changed


def check_private_robot(node_class, make_context, rt=None) -> CheckReport:
    """Check the student's ``PrivateRobot`` and ``private_context`` in the spare domain.

    Args:
        node_class: the student's Node subclass, built as ``node_class(context=...)``.
        make_context: the student's ``private_context(domain_id)``.
        rt: the course runtime (default: this kernel's).

    Returns:
        A :class:`CheckReport`. It passes when the function leaves ``os.environ`` and rclpy's
        signal handlers as they were (called with rclpy's own choice of handlers, as in a plain
        Python program) and returns an initialised context in the given domain; the
        node, built in that context, is named ``private_robot`` and publishes String on
        ``/robot_status``; a listener process in that domain hears it; and the kernel's domain
        never lists the node or its topic.
    """
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport("Exercise 07.1 - a robot the class cannot see")
    spare = reserve_spare_domain()
    environment = _ros_environment()
    handlers = get_current_signal_handlers_options()
    with rclpys_own_signal_default():  # what the function does outside a course kernel
        context = report.run("private_context(domain_id) runs", lambda: make_context(spare),
                             hint="Read the error; private_context receives the domain number as an int.")
    _check_kernel_kept(report, environment, handlers)
    if context is None:
        return report
    ours = isinstance(context, Context) and context is not rt.context
    try:
        if _check_context(report, rt, context, spare):
            _check_robot(report, rt, node_class, context, spare)
    finally:
        if ours and context is get_default_context():
            try_shutdown()  # rclpy's default context: a new one replaces it, so rclpy.init() works again
        elif ours and context.ok():
            context.try_shutdown()
    return report


def _check_kernel_kept(report: CheckReport, environment: dict[str, str], handlers) -> None:
    changed = _restore_environment(environment)  # put back at once: later children must not inherit it
    report.add("the kernel's environment is left as it was", not changed,
               f"changed: {', '.join(changed)} (the checker put them back)" if changed else "",
               hint="Every process this kernel starts later inherits os.environ. Find where the domain "
                    "can be given to the context itself: help(Context.init).")
    installed = get_current_signal_handlers_options() != handlers
    if installed and handlers == SignalHandlerOptions.NO:
        uninstall_signal_handlers()
    report.add("rclpy's signal handlers stay off", not installed,
               "rclpy's handlers were installed (the checker removed them again)" if installed else "",
               hint="Chapter 00, section 1: why the course's contexts run without rclpy's signal handler. "
                    "The checker calls private_context with rclpy.init choosing the handlers as rclpy "
                    "does outside this course: compare help(rclpy.init) with help(Context.init).")


def _check_context(report: CheckReport, rt, context, domain: int) -> bool:
    """The context criterion; True when the context runs (in any domain), so the robot can be tried."""
    if not isinstance(context, Context):
        report.add("private_context(domain_id) returns an initialised Context in that domain", False,
                   f"it returned {type(context).__name__}, not an rclpy Context",
                   hint="Return the context itself (from rclpy.context import Context).")
        return False
    if context is rt.context:
        report.add("private_context(domain_id) returns an initialised Context in that domain", False,
                   "that is the kernel's own context", hint="Create a new Context of your own.")
        return False
    if not context.ok():
        report.add("private_context(domain_id) returns an initialised Context in that domain", False,
                   "the context is not initialised (context.ok() is False)",
                   hint="A new Context does nothing until it is initialised: help(Context.init).")
        return False
    actual = context.get_domain_id()
    wrong = f"it is in domain {actual}, not in {domain}, the domain it was given"
    report.add("private_context(domain_id) returns an initialised Context in that domain", actual == domain,
               "" if actual == domain else wrong,
               hint="Which domain does a context join when nobody tells it? help(Context.init).")
    return True


def _check_robot(report: CheckReport, rt, node_class, context, team_domain: int) -> None:
    node = report.run("PrivateRobot(context=...) builds its node in that context",
                      lambda: node_class(context=context),
                      hint="help(Node): which argument of Node's constructor says where a node lives?")
    if node is None:
        return
    in_context = node.context is context
    if not report.add("PrivateRobot(context=...) builds its node in that context", in_context,
                      "" if in_context else "the node joined another context",
                      hint="help(Node): which argument of Node's constructor says where a node lives?"):
        node.destroy_node()  # it lives elsewhere: nothing below would test the private context
        return
    name = node.get_name()
    report.add(f"the node is named {ROBOT_NAME}", name == ROBOT_NAME,
               "" if name == ROBOT_NAME else f"its name is {name!r}",
               hint="The name is the first argument of super().__init__ in your constructor.")
    topics = dict(node.get_publisher_names_and_types_by_node(name, node.get_namespace()))
    right_type = topics.get(STATUS_TOPIC) == [STATUS_TYPE]
    publishes = report.add(f"it publishes {STATUS_TYPE} on {STATUS_TOPIC}", right_type,
                           "" if right_type else f"it publishes on: {', '.join(sorted(topics)) or 'nothing'}",
                           hint="Compare the topic name and message type of your publisher with the task.")
    errors: list[BaseException] = []
    try:
        # (one process cannot use a topic name with two types: the checker listens only to a String)
        periodic = _check_rate(report, node, context, errors) if publishes else report.add(
            RATE, False, "not tried: the robot must publish String first", hint="Fix the criterion above.")
        domain = context.get_domain_id()
        class_domain = rt.domain.domain_id
        report.add("the class cannot see it: its domain is not the class's", domain != class_domain,
                   f"it is in domain {domain}, the class in {class_domain}",
                   hint="The class sees everything in its own domain: which domain is your context in? "
                        "(Participants of different domains never discover each other.)")
        if not (publishes and periodic and domain == team_domain):
            report.add(TEAM_HEARS, False, "not tried: the robot must publish String periodically in its "
                       f"team's domain ({team_domain}) first", hint="Fix the criteria above first.")
        else:
            _check_team_hears(report, rt, node, context, team_domain, errors)
    finally:
        node.destroy_node()
    report.add("callbacks raised no errors", not errors,
               f"{type(errors[0]).__name__}: {errors[0]}" if errors else "",
               hint="Run the node's callback yourself once and read the traceback.")


def _check_rate(report: CheckReport, node, context, errors: list) -> bool:
    """The robot on a clock the checker owns, in its own context: how often it publishes in 1 s, exactly."""
    from std_msgs.msg import String

    clock = SimClock(context=context)
    heard: list = []
    try:
        clock.drive(node)
        listener = clock.drive(Node("_private_robot_check", context=context, enable_rosout=False,
                                    start_parameter_services=False))
        listener.create_subscription(String, STATUS_TOPIC, heard.append, 10)
        clock.wait_matched()
        heard.clear()
        clock.advance(RATE_WINDOW_S, 0.01)
        errors.extend(clock.errors)
    finally:
        driven = [n for n in clock.driven if n is not node]
        clock.close()
        for extra in driven:
            extra.destroy_node()
        node.set_parameters([Parameter("use_sim_time", Parameter.Type.BOOL, False)])
    expected = STATUS_HZ * RATE_WINDOW_S
    return report.add(RATE, abs(len(heard) - expected) <= 1,
                      f"{len(heard)} in {RATE_WINDOW_S:g} s of its clock",
                      hint="Does something publish again and again? Chapter 00 showed the usual way.")


def _check_team_hears(report: CheckReport, rt, node, context, team_domain: int, errors: list) -> None:
    """A listener process in the team's domain hears the robot: an event a hang bound only limits."""
    executor = SingleThreaded(context=context)
    executor.add_node(node)
    spinner = SpinThread(executor, "private-robot", errors.append).start()
    try:
        team = rt.spawn(TEAM_LISTENER, ReportingListener,
                        params={"name": TEAM_LISTENER, "topic": STATUS_TOPIC.lstrip("/")},
                        env={"ROS_DOMAIN_ID": str(team_domain)})
        heard = poll_until(lambda: len(heard_lines(team)) >= HEARD_MESSAGES, HANG_S)
        report.add(TEAM_HEARS, heard, "" if heard else f"nothing heard in {HANG_S:g} s",
                   hint="Is the listener's domain the one your context joined?")
    finally:
        rt.stop_child(TEAM_LISTENER)
        spinner.stop()
        executor.shutdown(timeout_sec=2)
