"""Checker of chapter 10 (capstone): a safety monitor that also obeys the fleet's e-stop.

The student extends the robot's :class:`~course_helpers.chapters.ch10_capstone.SafetyMonitor`
(built as ``MyMonitor(namespace)``) so that it also follows the fleet manager's e-stop on the
absolute topic ``/fleet/estop``. :func:`check_fleet_estop` runs two whole robots with it, in
the namespaces ``/robot4`` and ``/robot5``: the drivers (base and LIDAR) of each in a child
process, its navigator, gripper, mission runner and operator's e-stop button in the kernel,
the student's safety monitor beside them, and a
:class:`~course_helpers.chapters.ch10_capstone.FleetManager`. What each robot's
e-stop is, the checker reads from its navigator: a node of the robot, not the monitor itself.

1. the safety monitor can be created, and runs as ``safety_monitor`` under the namespace;
2. with no fleet stop, robot 4 starts released;
3. a fleet stop engages robot 4's e-stop and stops the mission it is driving;
4. robot 5, whose safety monitor starts only after the fleet stop, is stopped too;
5. while the fleet stop holds, robot 4's operator cannot release its e-stop;
6. the fleet's release releases both robots, and each completes a pick mission;
7. after a fleet stop and release, an e-stop that robot 4's operator pressed stays engaged,
   until that operator releases it.

A criterion whose failure makes the next ones meaningless ends the run.

Every e-stop message travels between nodes of this kernel (the fleet manager, the safety monitor, the
navigator, the operator's button), where a message is in its reader once ``publish()`` returns. So
after each step the checker lets the kernel's executor run everything that step made ready
(``rt.settle_callbacks``, a sentinel on the executor's queue) and then reads the navigator: "the
e-stop did not change" is exact, not "did not change within half a second". Missions involve the
robots' driver processes, so their ends are awaited as events (``MISSION_S`` only bounds a hang).
"""

from __future__ import annotations

from course_helpers.chapters.ch10_capstone import (
    EStopButton,
    FleetManager,
    MissionRunner,
    Robot,
    start_robots,
)
from course_helpers.checks import CheckReport
from course_helpers.core.errors import CourseError
from course_helpers.core.names import full_name
from course_helpers.core.waiting import poll_until

FLEET = ("robot4", "robot5")
HOPS = 3  # /fleet/estop -> the safety monitor -> the robot's estop topic -> its navigator: rounds to settle
HANG_S = 30.0  # s; bounds a hang only: a late-joining monitor gets the kept fleet stop within moments
MISSION_S = 30.0  # s; a pick mission of the fleet's robots takes about 3 s (a hang bound too)


def heard(robot: Robot) -> str:
    """The e-stop state the robot's navigator heard last: 'unknown', 'engaged' or 'released'."""
    msg = robot.navigator.estop
    return "unknown" if msg is None else ("engaged" if msg.engaged else "released")


def check_fleet_estop(monitor_class, rt=None) -> CheckReport:
    """Run two robots with ``monitor_class`` as their safety monitor under a fleet manager.

    ``monitor_class(namespace)`` builds the monitor; ``rt`` is the runtime (the kernel's by
    default). Returns a :class:`CheckReport` (see the module docstring for the criteria).
    """
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport("Exercise 10 - a fleet-wide e-stop")
    added = []  # the kernel's nodes of the run, removed afterwards with the robots' processes
    try:
        _run(report, rt, monitor_class, added)
    finally:
        rt.stop_children(FLEET)
        for node in reversed(added):
            rt.remove(node)
        for name in FLEET:  # a robot whose start failed half-way
            for node in ("navigator", "gripper"):
                rt.remove(full_name(f"/{name}", node))
    return report


def _run(report: CheckReport, rt, monitor_class, added: list) -> None:
    def add(node_class, *args):
        added.append(rt.add(node_class, *args, console=False))
        return added[-1]

    manager = add(FleetManager)
    robots = start_robots(rt, list(FLEET), camera=False, safety_monitor=False)
    added.extend(node for robot in robots for node in (robot.navigator, robot.gripper))
    runners = [add(MissionRunner, r.namespace) for r in robots]
    buttons = [add(EStopButton, r.namespace) for r in robots]
    four, five = robots

    created = "your safety monitor runs in a robot's namespace"
    monitor = report.run(created, lambda: add(monitor_class, four.namespace),
                         hint="Run the cell with your class first. The checker builds it like the robot's "
                              "own: YourClass('/robot4'); the error above says what went wrong.")
    if monitor is None:
        return
    where = monitor.get_fully_qualified_name()
    if not report.add(created, where == full_name(four.namespace, "safety_monitor"), f"it runs as {where}",
                      hint="The operator's button calls safety_monitor/engage in the robot's namespace: "
                           "keep the name SafetyMonitor gives the node."):
        return

    rt.settle_callbacks(HOPS)  # whatever the constructor published has reached the navigator
    released = heard(four) == "released"
    if not report.add("with no fleet stop, the robot starts released", released,
                      f"robot4's navigator hears: {heard(four)}",
                      hint="No fleet stop has been sent yet. Compare what your constructor publishes "
                           "with what SafetyMonitor's does."):
        return

    stop_criterion = "a fleet stop engages the robot's e-stop and stops its mission"
    mission = runners[0].start("crate-1", shelf="A2")
    if not poll_until(lambda: mission.progress > 0.05 or mission.finished, MISSION_S):
        report.add(stop_criterion, False, f"robot4's mission did not get under way: {mission.state}",
                   hint="Before any fleet stop, the robot must drive as it did with SafetyMonitor.")
        return
    manager.stop("fire drill")
    rt.settle_callbacks(HOPS)
    stopped = heard(four) == "engaged"
    halted = stopped and _ended(mission) is False
    detail = (f"robot4's e-stop is engaged; its mission: {mission.state}" if stopped
              else f"robot4's navigator still hears '{heard(four)}' after the fleet stop went round")
    if not report.add(stop_criterion, halted, detail,
                      hint="The fleet manager publishes on /fleet/estop: %ros2 topic info -v /fleet/estop "
                           "lists who publishes and who listens there."):
        return

    late_monitor = add(monitor_class, five.namespace)
    late = _gets_the_kept_stop(rt, late_monitor, five)
    report.add("a robot whose safety monitor starts after the fleet stop is stopped too", late,
               f"robot5's navigator hears: {heard(five)}",
               hint="The fleet stop was sent before robot 5's monitor existed. Section 6, 'A node that "
                    "joins late', shows what lets a late node still receive it.")

    _press(buttons[0], engage=False)
    rt.settle_callbacks(HOPS)
    held = heard(four) == "engaged"
    report.add("while the fleet stop holds, the robot's operator cannot release it", held,
               f"after the operator's release, robot4's navigator hears: {heard(four)}",
               hint="An operator's release comes in through the ~/engage service: see "
                    "SafetyMonitor.on_engage.")

    manager.release()
    rt.settle_callbacks(HOPS)
    both = heard(four) == heard(five) == "released"
    missions = [runner.start(f"crate-{i + 2}", shelf)
                for i, (runner, shelf) in enumerate(zip(runners, ("A1", "B1"), strict=True))] if both else []
    delivered = [_ended(m) for m in missions]
    undelivered = "".join(f"; {robot.namespace[1:]}: {m.state}"
                          for robot, m, ok in zip(robots, missions, delivered, strict=False) if not ok)
    if not report.add("the fleet's release lets every robot it stopped drive again",
                      both and all(delivered),
                      f"missions delivered: {sum(map(bool, delivered))} of 2{undelivered}" if both else
                      f"robot4's navigator hears '{heard(four)}', robot5's '{heard(five)}' after the "
                      "fleet's release went round",
                      hint="The fleet manager publishes on the same topic when it releases the fleet stop."):
        return

    _press(buttons[0], engage=True)
    rt.settle_callbacks(HOPS)
    pressed = heard(four) == "engaged"
    manager.stop("second drill")
    manager.release()
    rt.settle_callbacks(HOPS)
    passed_on = heard(five) == "released"  # the release has gone out
    kept = pressed and passed_on and heard(four) == "engaged"
    after_fleet = heard(four)
    _press(buttons[0], engage=False)
    rt.settle_callbacks(HOPS)
    freed = kept and heard(four) == "released"
    report.add("a fleet release leaves the operator's own e-stop engaged, until the operator releases it",
               kept and freed,
               f"after the fleet's release robot4's navigator heard '{after_fleet}', after the operator's "
               f"release '{heard(four)}'",
               hint="Who engaged the e-stop? self.current holds the message the monitor published last.")


def _gets_the_kept_stop(rt, monitor, robot: Robot) -> bool:
    """Whether a monitor that starts after the fleet stop gets it: only a TRANSIENT_LOCAL subscription to
    /fleet/estop is handed what the manager kept (by construction); one that is, gets it a moment
    after it matches (an event: ``HANG_S`` only bounds a hang)."""
    from rclpy.qos import DurabilityPolicy

    fleet = [sub for sub in monitor.subscriptions if sub.topic_name == "/fleet/estop"]
    if not fleet or fleet[0].qos_profile.durability != DurabilityPolicy.TRANSIENT_LOCAL:
        rt.settle_callbacks(HOPS)
        return heard(robot) == "engaged"  # what it published itself, if anything
    return poll_until(lambda: heard(robot) == "engaged", HANG_S)


def _ended(mission) -> bool | None:
    """True if ``mission`` succeeded, False if it failed, None if it did not end in time."""
    try:
        return mission.wait(timeout=MISSION_S)
    except CourseError:
        return None


def _press(button: EStopButton, engage: bool) -> None:
    """Press (or release) the operator's button; a monitor that does not answer is judged by its e-stop."""
    try:
        if engage:
            button.press()
        else:
            button.release()
    except CourseError:
        pass
