"""Reference solution of chapter 05 (actions); CI checks it with ``checks.ch05_actions``."""

from __future__ import annotations

import math

from course_interfaces.action import Navigate
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node

from course_helpers.chapters.ch05_actions import sleep_async

MAX_SPEED = 1.5  # fastest allowed cruise speed [m/s]
STEP_S = 0.1  # control period: one step and one feedback message every 0.1 s


class NavigationServer(Node):
    """Exercise 05: drives a simulated robot from the dock (0, 0) straight to a target point."""

    def __init__(self):
        super().__init__('navigation_server')
        self.server = ActionServer(self, Navigate, 'navigate', self.execute,
                                   goal_callback=self.on_goal, cancel_callback=self.on_cancel)

    def on_goal(self, goal: Navigate.Goal) -> GoalResponse:
        if 0.0 < goal.speed <= MAX_SPEED:
            return GoalResponse.ACCEPT
        self.get_logger().warning(f'rejected: speed {goal.speed} m/s is not in (0, {MAX_SPEED}]')
        return GoalResponse.REJECT

    def on_cancel(self, goal_handle) -> CancelResponse:
        return CancelResponse.ACCEPT

    async def execute(self, goal_handle) -> Navigate.Result:
        goal = goal_handle.request
        distance = math.hypot(goal.target.x, goal.target.y)  # [m] from the dock
        travelled = 0.0  # [m]
        feedback = Navigate.Feedback()
        while travelled < distance:
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                return Navigate.Result(success=False, distance_travelled=travelled)
            await sleep_async(self, STEP_S)  # frees the executor for other callbacks meanwhile
            travelled = min(distance, travelled + goal.speed * STEP_S)
            feedback.distance_remaining = distance - travelled
            feedback.progress = travelled / distance
            goal_handle.publish_feedback(feedback)
        goal_handle.succeed()
        return Navigate.Result(success=True, distance_travelled=travelled)

    def destroy_node(self):
        self.server.destroy()  # Node.destroy_node() leaves action servers alive
        super().destroy_node()
