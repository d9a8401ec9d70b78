"""The robot's navigator: the ``navigate`` action server (course_interfaces/action/Navigate).

It drives the base to a point through ``cmd_vel``, reports progress as feedback, can be
cancelled, and aborts when the e-stop is engaged. A goal succeeds once the base stands still at the
target: odometry sent after the stop command shows it at rest there, so whatever acts next (the
gripper) finds the robot where the navigator says it is, however late the messages come. It runs
in the kernel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from course_interfaces.action import Navigate
from course_interfaces.msg import EStop
from geometry_msgs.msg import Twist, Vector3
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import SetParametersResult
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.parameter import Parameter
from rclpy.task import Future
from rclpy.time import Time

from course_helpers.chapters.ch10_capstone.channels import COMMAND_QOS, ODOM_QOS
from course_helpers.chapters.ch10_capstone.robot import RobotNode
from course_helpers.chapters.ch10_capstone.warehouse import SPEED_LIMIT


@dataclass
class Drive:
    """The goal being driven: its handle, target [m], speed [m/s], the distance so far [m],
    ``done``, the future that the execute callback awaits and the control loop completes, and
    ``stopped_at``, when the stop command at the target was sent (None while driving)."""

    goal_handle: object
    target: tuple[float, float]
    speed: float
    start_distance: float
    last_pose: tuple[float, float]
    done: Future
    travelled: float = 0.0
    stopped_at: Time | None = None


class Navigator(RobotNode):
    """Action server ``navigate``: drives the base to a point with feedback, cancel and e-stop abort.

    The control loop is a 20 Hz timer; the execute callback is a coroutine that awaits
    the loop's verdict, so one single-threaded executor runs everything. Within
    ``goal_tolerance`` of the target it commands a stop, and the goal succeeds at the first
    odometry stamped after that stop that shows the base at rest within tolerance (the base may
    still have been moving on older commands; if it stopped too far, the loop drives on).
    """

    def __init__(self, namespace: str = ""):
        super().__init__("navigator", namespace)
        self.max_speed = self.declare_parameter("max_speed", 1.5).value  # [m/s]
        self.tolerance = self.declare_parameter("goal_tolerance", 0.05).value  # [m]
        self.add_on_set_parameters_callback(self.check_parameters)
        self.pose: tuple[float, float] | None = None
        self.at_rest = False  # the last odometry's velocity was zero
        self.odom_stamp: Time | None = None  # when the base sent the last odometry
        self.active: Drive | None = None
        self.cmd_publisher = self.create_publisher(Twist, "cmd_vel", COMMAND_QOS)
        self.odom_subscription = self.create_subscription(Odometry, "odom", self.on_odom, ODOM_QOS)
        self.server = ActionServer(self, Navigate, "navigate", execute_callback=self.execute,
                                   goal_callback=self.on_goal, cancel_callback=self.on_cancel)
        self.timer = self.create_timer(0.05, self.control_step)  # 20 Hz
        self.set_state("idle")

    def destroy_node(self) -> None:
        # rclpy's destroy_node() leaves action servers alive (and the node in the graph);
        # destroy ours first, unless whoever destroys the node already did.
        if self.server in list(self.waitables):
            self.server.destroy()
        super().destroy_node()

    def check_parameters(self, params: list[Parameter]) -> SetParametersResult:
        for param in params:
            if param.name == "max_speed":
                if not isinstance(param.value, float) or not 0.0 < param.value <= SPEED_LIMIT:
                    return SetParametersResult(
                        successful=False,
                        reason=f"max_speed must be a float in (0, {SPEED_LIMIT}] m/s")
                self.max_speed = param.value
            elif param.name == "goal_tolerance":
                self.tolerance = float(param.value)
        return SetParametersResult(successful=True)

    def on_odom(self, msg: Odometry) -> None:
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y)
        velocity = msg.twist.twist.linear  # [m/s]
        self.at_rest = velocity.x == 0.0 and velocity.y == 0.0
        self.odom_stamp = Time.from_msg(msg.header.stamp)

    def on_goal(self, goal: Navigate.Goal) -> GoalResponse:
        if self.estop_engaged or self.pose is None:
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def on_cancel(self, _goal_handle) -> CancelResponse:
        return CancelResponse.ACCEPT

    async def execute(self, goal_handle) -> Navigate.Result:
        if self.active is not None:
            self.finish("preempted")
        target = (goal_handle.request.target.x, goal_handle.request.target.y)
        distance = math.dist(self.pose, target)
        drive = Drive(goal_handle, target, goal_handle.request.speed, max(distance, 1e-6),
                      self.pose, Future())
        self.active = drive
        self.set_state(f"navigating to ({target[0]:.1f}, {target[1]:.1f})")
        outcome = await drive.done
        if outcome == "succeeded":
            goal_handle.succeed()
        elif outcome == "canceled":
            goal_handle.canceled()
        else:
            goal_handle.abort()
        return Navigate.Result(success=outcome == "succeeded", distance_travelled=drive.travelled)

    def control_step(self) -> None:
        drive = self.active
        if drive is None or self.pose is None:
            return
        if drive.goal_handle.is_cancel_requested:
            self.finish("canceled")
            return
        if self.estop_engaged:
            self.finish("aborted (e-stop)")
            return
        drive.travelled += math.dist(drive.last_pose, self.pose)
        drive.last_pose = self.pose
        dx, dy = drive.target[0] - self.pose[0], drive.target[1] - self.pose[1]
        remaining = math.hypot(dx, dy)
        if remaining <= self.tolerance:
            if drive.stopped_at is None:
                drive.stopped_at = self.get_clock().now()
            self.cmd_publisher.publish(Twist())  # stop here
            if self.at_rest and self.odom_stamp > drive.stopped_at:  # it has stopped here: arrived
                self.finish("succeeded")
            return
        drive.stopped_at = None  # not (or no longer) at the target: drive
        cruise = min(drive.speed if drive.speed > 0 else self.max_speed, self.max_speed)
        speed = max(0.05, min(cruise, 3.0 * remaining))  # near the goal: 3 m/s per metre left
        self.cmd_publisher.publish(Twist(linear=Vector3(x=speed * dx / remaining, y=speed * dy / remaining)))
        drive.goal_handle.publish_feedback(Navigate.Feedback(
            distance_remaining=remaining,
            progress=max(0.0, min(1.0, 1.0 - remaining / drive.start_distance))))

    def finish(self, outcome: str) -> None:
        drive, self.active = self.active, None
        self.cmd_publisher.publish(Twist())  # stop
        if drive is not None and not drive.done.done():
            drive.done.set_result(outcome)
        self.set_state("idle" if outcome in ("succeeded", "canceled") else f"goal {outcome}")

    def on_estop(self, msg: EStop) -> None:
        if msg.engaged and self.active is not None:
            self.finish("aborted (e-stop)")
        elif not msg.engaged and self.state.startswith("goal aborted"):
            self.set_state("idle")
