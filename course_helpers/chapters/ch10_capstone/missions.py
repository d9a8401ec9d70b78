"""Pick missions: drive to a shelf (action ``navigate``), pick (service ``pick_item``), drive home
and put the item down there (service ``place_item``).

:class:`MissionRunner` is the robot's client of both; :class:`Mission` is what it hands
back at once, filled in as the mission runs in the executor.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from action_msgs.msg import GoalStatus
from course_interfaces.action import Navigate
from course_interfaces.msg import EStop
from course_interfaces.srv import PickItem
from geometry_msgs.msg import Point
from rclpy.action import ActionClient
from std_msgs.msg import String
from std_srvs.srv import Trigger

from course_helpers.chapters.ch10_capstone.channels import LATCHED_QOS
from course_helpers.chapters.ch10_capstone.robot import RobotNode
from course_helpers.chapters.ch10_capstone.warehouse import SHELVES, home_of
from course_helpers.core.errors import CourseError


@dataclass
class Mission:
    """A pick mission: drive to the shelf, pick, drive home, place the item there.

    Filled in by :class:`MissionRunner`."""

    item_id: str
    shelf: str
    state: str = "queued"
    progress: float = 0.0
    steps: list[str] = field(default_factory=list)
    success: bool | None = None
    listeners: list[Callable[[Mission], None]] = field(default_factory=list, repr=False)
    finished_event: threading.Event = field(default_factory=threading.Event, repr=False)

    @property
    def finished(self) -> bool:
        return self.finished_event.is_set()

    def update(self, state: str | None = None, progress: float | None = None, step: str | None = None):
        """Change the state text, the progress (0..1) or add a step; then tell every listener."""
        if state is not None:
            self.state = state
        if progress is not None:
            self.progress = progress
        if step is not None:
            self.steps.append(step)
        for listener in list(self.listeners):
            listener(self)

    def wait(self, timeout: float = 30.0) -> bool:
        """Block (without spinning) until the mission ends; return whether it succeeded."""
        if not self.finished_event.wait(timeout):
            raise CourseError(f"mission {self.item_id}@{self.shelf} still '{self.state}' "
                              f"after {timeout:g} s")
        return bool(self.success)


class MissionRunner(RobotNode):
    """Runs pick missions with the navigator (action) and the gripper (services).

    ``start(item_id, shelf)`` returns a :class:`Mission` at once; the mission runs as a
    coroutine in the executor and reports progress from the action's feedback.
    """

    LEGS = {"to_shelf": (0.0, 0.45), "home": (0.55, 1.0)}  # the share of the mission each drive covers

    def __init__(self, namespace: str = "", home: list[float] | None = None):
        super().__init__("mission_runner", namespace)
        self.home = tuple(home or home_of(namespace))
        self.navigate = ActionClient(self, Navigate, "navigate")
        self.pick = self.create_client(PickItem, "pick_item")
        self.place = self.create_client(Trigger, "place_item")
        self.status_publisher = self.create_publisher(String, "mission/status", LATCHED_QOS)
        self.current: Mission | None = None
        self.goal_handle = None
        self.set_state("idle")

    def destroy_node(self) -> None:
        if self.navigate in list(self.waitables):  # action clients outlive destroy_node() too
            self.navigate.destroy()
        super().destroy_node()

    def start(self, item_id: str, shelf: str, timeout: float = 10.0) -> Mission:
        """Start a mission (waits up to ``timeout`` s for the navigator and gripper to be up)."""
        if shelf not in SHELVES:
            raise CourseError(f"unknown shelf {shelf!r}; shelves: {', '.join(sorted(SHELVES))}")
        if self.current is not None and not self.current.finished:
            raise CourseError(f"a mission is running ({self.current.item_id}@{self.current.shelf}); "
                              "wait for it or cancel it with runner.cancel()")
        if not self.navigate.wait_for_server(timeout_sec=timeout):
            raise CourseError(f"no navigate action server under {self.get_namespace()} "
                              f"after {timeout:g} s")
        for client in (self.pick, self.place):
            if not client.wait_for_service(timeout_sec=timeout):
                raise CourseError(f"no {client.srv_name} service under {self.get_namespace()} "
                                  f"after {timeout:g} s")
        if self.executor is None:
            raise CourseError("the mission runner is not spinning: add it with "
                              "rt.add(MissionRunner, '/robot1') first")
        mission = Mission(item_id, shelf)
        self.current = mission
        self.executor.create_task(self.run, mission)
        return mission

    def cancel(self) -> None:
        """Ask the navigator to cancel the current leg (the mission then ends as canceled)."""
        if self.goal_handle is not None:
            self.goal_handle.cancel_goal_async()

    async def run(self, mission: Mission) -> None:
        self.report(mission, f"driving to shelf {mission.shelf}", 0.0)
        if not await self.drive(mission, SHELVES[mission.shelf], "to_shelf"):
            return
        self.report(mission, f"picking {mission.item_id}", 0.5)
        response = await self.pick.call_async(PickItem.Request(item_id=mission.item_id,
                                                               shelf=mission.shelf))
        if not response.success:
            self.end(mission, False, f"pick failed: {response.message}")
            return
        mission.update(step=response.message)
        self.report(mission, "returning home", 0.55)
        if not await self.drive(mission, self.home, "home"):
            return
        placed = await self.place.call_async(Trigger.Request())
        if not placed.success:
            self.end(mission, False, f"place failed: {placed.message}")
            return
        mission.update(step=placed.message)
        self.end(mission, True, f"delivered {mission.item_id}")

    async def drive(self, mission: Mission, point, leg: str) -> bool:
        low, high = self.LEGS[leg]

        def on_feedback(feedback_msg) -> None:
            done = feedback_msg.feedback.progress
            mission.update(progress=low + (high - low) * done)

        goal = Navigate.Goal(target=Point(x=float(point[0]), y=float(point[1])), speed=0.0)
        self.goal_handle = await self.navigate.send_goal_async(goal, feedback_callback=on_feedback)
        if not self.goal_handle.accepted:
            reason = "e-stop engaged" if self.estop_engaged else "navigator refused the goal"
            self.end(mission, False, f"navigation goal rejected ({reason})")
            return False
        outcome = await self.goal_handle.get_result_async()
        self.goal_handle = None
        if outcome.status != GoalStatus.STATUS_SUCCEEDED:
            where = f"shelf {mission.shelf}" if leg == "to_shelf" else "home"
            why = {GoalStatus.STATUS_ABORTED: "aborted", GoalStatus.STATUS_CANCELED: "canceled"}.get(
                outcome.status, f"status {outcome.status}")
            extra = " (e-stop engaged)" if self.estop_engaged else ""
            self.end(mission, False, f"navigation to {where} {why}{extra}")
            return False
        mission.update(progress=high,
                       step="reached " + (f"shelf {mission.shelf}" if leg == "to_shelf" else "home"))
        return True

    def report(self, mission: Mission, state: str, progress: float) -> None:
        mission.update(state=state, progress=progress, step=state)
        self.set_state(f"mission {mission.item_id}@{mission.shelf}: {state}")
        self.status_publisher.publish(String(data=self.state))

    def end(self, mission: Mission, success: bool, text: str) -> None:
        mission.success = success
        mission.update(state=("done: " if success else "failed: ") + text,
                       progress=1.0 if success else mission.progress, step=text)
        self.set_state(f"mission {mission.item_id}@{mission.shelf} {'done' if success else 'FAILED'}")
        self.status_publisher.publish(String(data=mission.state))
        mission.finished_event.set()

    def on_estop(self, msg: EStop) -> None:
        busy = self.current is not None and not self.current.finished
        if msg.engaged and not busy:
            self.set_state("idle (e-stop engaged)")
        elif not msg.engaged and not busy:
            self.set_state("idle")
