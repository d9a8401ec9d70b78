"""The warehouse robot of chapter 10 (capstone): its nodes, its QoS per channel, and its tools.

One robot is a set of ordinary rclpy nodes under a namespace (``/robot1``):

============== ============================================ =============================
node           does                                         runs
============== ============================================ =============================
camera         30 Hz ``camera/image_raw`` (sensor_msgs/Image) child process (the robot)
lidar          10 Hz ``scan`` (sensor_msgs/LaserScan)        child process (the robot)
base           ``cmd_vel`` in, ``odom`` out (nav_msgs)       child process (the robot)
safety_monitor ``estop`` (RELIABLE + TRANSIENT_LOCAL)        child process (the robot)
navigator      action ``navigate`` (course_interfaces)       kernel
gripper        service ``pick_item`` (course_interfaces)     kernel
mission_runner action + service client, ``mission/status``   kernel
perception     ``camera/image_raw`` -> ``perception/...``    child process (section 6)
============== ============================================ =============================

Every node follows the e-stop: it subscribes to ``estop`` with the e-stop QoS
(so a node that starts late learns the current state at once), treats an
unknown state as engaged (fail safe), and publishes what it is doing on its
latched ``~/_state`` topic, which :class:`StateBoard` collects into a table (the
leading underscore hides it, like other infrastructure, from the graph view and
``%ros2 topic list``; ``%ros2 topic echo /robot1/base/_state`` still shows it).

The module also holds the measurement used in the troubleshooting section
(:func:`measure_delivery`), the two detectors whose speed the student compares,
the fleet-domain probe (:func:`nodes_in_domain`) and the helpers the design
checker (``checks/capstone.py``) uses to read QoS from the live graph.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import rclpy
from action_msgs.msg import GoalStatus
from course_interfaces.action import Navigate
from course_interfaces.msg import EStop
from course_interfaces.srv import PickItem
from geometry_msgs.msg import Point, PointStamped, Twist
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import SetParametersResult
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from sensor_msgs.msg import Image, LaserScan
from std_msgs.msg import String
from std_srvs.srv import SetBool

from course_helpers.core.errors import CourseError, WaitTimeout

# ---------------------------------------------------------------------------------- QoS per channel
# Sensor streams: a late frame is worthless and a lost one is replaced 33 ms later.
SENSOR_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5,
                        reliability=ReliabilityPolicy.BEST_EFFORT,
                        durability=DurabilityPolicy.VOLATILE)
# Velocity commands and odometry: every message matters while it is fresh; old ones are stale.
COMMAND_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
ODOM_QOS = COMMAND_QOS
# States that a node joining later must still learn: the e-stop, node states, mission status.
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
ESTOP_QOS = LATCHED_QOS

# ---------------------------------------------------------------------------------- the warehouse
WALLS = (-3.0, -3.0, 7.0, 5.0)  # x_min, y_min, x_max, y_max of the building [m]
SHELVES = {  # pick positions in the map frame [m]
    "A1": (1.5, 1.0),
    "A2": (3.0, 1.0),
    "B1": (1.5, -1.0),
    "B2": (2.5, -1.0),
}
HOMES = {"robot1": (0.0, 0.0), "robot2": (0.0, 2.5), "robot3": (0.0, -2.0)}
SPEED_LIMIT = 2.0  # the fastest any robot may be told to go [m/s]

CAMERA_TOPIC = "camera/image_raw"
DETECTIONS_TOPIC = "perception/detections"
STATE_TOPIC = "~/_state"  # hidden (leading underscore): infrastructure for the state board


def full_name(namespace: str, name: str) -> str:
    """`/ns` + `name` -> `/ns/name` (a bare name in the root namespace -> `/name`)."""
    return f"{namespace.rstrip('/')}/{name}" if namespace not in ("", "/") else f"/{name}"


# ---------------------------------------------------------------------------------- base class
class RobotNode(Node):
    """A robot node that follows the e-stop and publishes its state on the latched ``~/_state``."""

    def __init__(self, name: str, namespace: str = "", follow_estop: bool = True):
        super().__init__(name, namespace=namespace)
        self.state = ""
        self.estop: EStop | None = None  # None until the safety monitor has been heard
        self.state_publisher = self.create_publisher(String, STATE_TOPIC, LATCHED_QOS)
        if follow_estop:
            self.estop_subscription = self.create_subscription(
                EStop, "estop", self.on_estop_message, ESTOP_QOS)

    @property
    def estop_engaged(self) -> bool:
        """True while the e-stop is engaged, and also while its state is unknown (fail safe)."""
        return self.estop is None or self.estop.engaged

    def on_estop_message(self, msg: EStop) -> None:
        changed = self.estop is None or self.estop.engaged != msg.engaged
        self.estop = msg
        if changed:
            self.on_estop(msg)

    def on_estop(self, msg: EStop) -> None:
        """React to an e-stop change (subclasses override)."""

    def set_state(self, text: str) -> None:
        """Publish ``text`` on ``~/_state`` when it changes (latched: late readers get it too)."""
        if text != self.state:
            self.state = text
            self.state_publisher.publish(String(data=text))


# ---------------------------------------------------------------------------------- sensors
def make_frame(count: int, width: int = 160, height: int = 120) -> np.ndarray:
    """A synthetic mono8 camera frame: a dim gradient and a bright 16x16 item tag that moves."""
    frame = np.tile(np.linspace(10, 120, width, dtype=np.uint8), (height, 1))
    angle = count * 0.05
    x = int(width / 2 + width / 4 * math.cos(angle)) - 8
    y = int(height / 2 + height / 4 * math.sin(angle)) - 8
    frame[y:y + 16, x:x + 16] = 250
    return frame


class CameraDriver(RobotNode):
    """Publishes a small mono8 image at ``rate_hz`` (default 30 Hz) with the sensor-data QoS."""

    def __init__(self, namespace: str = "", rate_hz: float = 30.0, width: int = 160, height: int = 120):
        super().__init__("camera", namespace)
        self.rate_hz = self.declare_parameter("rate_hz", rate_hz).value
        self.width, self.height = width, height
        self.count = 0
        self.publisher = self.create_publisher(Image, CAMERA_TOPIC, SENSOR_QOS)
        self.timer = self.create_timer(1.0 / self.rate_hz, self.tick)  # 33 ms at 30 Hz
        self.set_state("streaming")

    def tick(self) -> None:
        frame = make_frame(self.count, self.width, self.height)
        msg = Image(height=self.height, width=self.width, encoding="mono8", step=self.width)
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = "camera_optical"
        msg.data = frame.tobytes()
        self.publisher.publish(msg)
        self.count += 1

    def on_estop(self, msg: EStop) -> None:
        # Sensors stay on during an e-stop: people need to see what the robot sees.
        self.set_state("streaming (e-stop engaged)" if msg.engaged else "streaming")


class LidarDriver(RobotNode):
    """Publishes a 360° scan of the walls (and any ``obstacles`` [x, y, radius, ...]) at 10 Hz."""

    def __init__(self, namespace: str = "", rate_hz: float = 10.0, beams: int = 180,
                 home: list[float] | None = None):
        super().__init__("lidar", namespace)
        self.declare_parameter("obstacles", Parameter.Type.DOUBLE_ARRAY)  # [x, y, r, x, y, r, ...]
        self.range_max = 12.0  # [m]
        self.angles = np.linspace(-math.pi, math.pi, beams, endpoint=False)
        self.pose = tuple(home or (0.0, 0.0))
        self.publisher = self.create_publisher(LaserScan, "scan", SENSOR_QOS)
        self.odom_subscription = self.create_subscription(Odometry, "odom", self.on_odom, ODOM_QOS)
        self.timer = self.create_timer(1.0 / rate_hz, self.tick)
        self.set_state("scanning")

    def on_odom(self, msg: Odometry) -> None:
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y)

    def obstacles(self) -> list[tuple[float, float, float]]:
        try:
            values = list(self.get_parameter("obstacles").value or [])
        except Exception:  # declared without a value: no obstacles
            values = []
        return [tuple(values[i:i + 3]) for i in range(0, len(values) - 2, 3)]

    def tick(self) -> None:
        ranges = cast_rays(self.pose, self.angles, self.obstacles(), self.range_max)
        msg = LaserScan(angle_min=float(self.angles[0]), angle_max=float(self.angles[-1]),
                        angle_increment=float(self.angles[1] - self.angles[0]),
                        range_min=0.05, range_max=self.range_max)
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = "laser"
        msg.ranges = ranges.astype(np.float32).tolist()
        self.publisher.publish(msg)

    def on_estop(self, msg: EStop) -> None:
        self.set_state("scanning (e-stop engaged)" if msg.engaged else "scanning")


def cast_rays(pose, angles: np.ndarray, obstacles, range_max: float) -> np.ndarray:
    """Distances [m] from ``pose`` along each angle to the walls or the nearest round obstacle."""
    x, y = pose
    dx, dy = np.cos(angles), np.sin(angles)
    x_min, y_min, x_max, y_max = WALLS
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(dx > 0, (x_max - x) / dx, np.where(dx < 0, (x_min - x) / dx, np.inf))
        ty = np.where(dy > 0, (y_max - y) / dy, np.where(dy < 0, (y_min - y) / dy, np.inf))
    ranges = np.minimum(tx, ty)
    for ox, oy, radius in obstacles:
        along = dx * (ox - x) + dy * (oy - y)
        disc = along ** 2 - ((ox - x) ** 2 + (oy - y) ** 2 - radius ** 2)
        hit = (disc >= 0) & (along > 0)
        t = np.where(hit, along - np.sqrt(np.maximum(disc, 0.0)), np.inf)
        ranges = np.minimum(ranges, np.where(t > 0, t, np.inf))
    return np.clip(ranges, 0.0, range_max)


# ---------------------------------------------------------------------------------- base and safety
class BaseController(RobotNode):
    """An omnidirectional base: integrates ``cmd_vel`` into ``odom`` at 20 Hz; halts on e-stop."""

    def __init__(self, namespace: str = "", home: list[float] | None = None):
        super().__init__("base", namespace)
        self.speed_limit = self.declare_parameter("speed_limit", SPEED_LIMIT).value  # [m/s]
        self.cmd_timeout = self.declare_parameter("cmd_timeout", 0.5).value  # [s] dead-man
        self.x, self.y = (home or (0.0, 0.0))
        self.vx = self.vy = 0.0
        self.last_cmd = -math.inf
        self.period = 0.05  # 20 Hz
        self.cmd_subscription = self.create_subscription(Twist, "cmd_vel", self.on_cmd, COMMAND_QOS)
        self.odom_publisher = self.create_publisher(Odometry, "odom", ODOM_QOS)
        self.timer = self.create_timer(self.period, self.step)
        self.set_state("waiting for safety monitor")

    def on_cmd(self, msg: Twist) -> None:
        if self.estop_engaged:
            return  # commands are ignored while the e-stop is engaged (or unknown)
        speed = math.hypot(msg.linear.x, msg.linear.y)
        scale = min(1.0, self.speed_limit / speed) if speed > 0 else 0.0
        self.vx, self.vy = msg.linear.x * scale, msg.linear.y * scale
        self.last_cmd = time.monotonic()

    def step(self) -> None:
        if self.estop_engaged or time.monotonic() - self.last_cmd > self.cmd_timeout:
            self.vx = self.vy = 0.0
        self.x += self.vx * self.period
        self.y += self.vy * self.period
        odom = Odometry()
        odom.header.stamp = self.get_clock().now().to_msg()
        odom.header.frame_id = "odom"
        odom.child_frame_id = "base_link"
        odom.pose.pose.position.x, odom.pose.pose.position.y = self.x, self.y
        odom.pose.pose.orientation.w = 1.0
        odom.twist.twist.linear.x, odom.twist.twist.linear.y = self.vx, self.vy
        self.odom_publisher.publish(odom)
        if self.estop_engaged:
            self.set_state("halted (e-stop)" if self.estop is not None else "waiting for safety monitor")
        else:
            self.set_state("driving" if (self.vx or self.vy) else "idle")

    def on_estop(self, msg: EStop) -> None:
        if msg.engaged:
            self.vx = self.vy = 0.0  # stop now, not at the next timer tick
        self.step()


class SafetyMonitor(RobotNode):
    """The single publisher of ``estop``: an operator service and a LIDAR proximity check.

    ``~/engage`` (std_srvs/SetBool): ``data: true`` engages, ``false`` releases. A scan
    with any range below ``stop_distance`` engages it too; only an operator releases it.
    """

    def __init__(self, namespace: str = ""):
        super().__init__("safety_monitor", namespace, follow_estop=False)
        self.stop_distance = self.declare_parameter("stop_distance", 0.4).value  # [m]
        self.publisher = self.create_publisher(EStop, "estop", ESTOP_QOS)
        self.engage_service = self.create_service(SetBool, "~/engage", self.on_engage)
        self.scan_subscription = self.create_subscription(LaserScan, "scan", self.on_scan, SENSOR_QOS)
        self.engaged = False
        self.publish_estop(False, "", "safety_monitor")  # latched: everyone learns "released"

    def publish_estop(self, engaged: bool, reason: str, source: str) -> None:
        self.engaged = engaged
        self.publisher.publish(EStop(engaged=engaged, reason=reason, source=source))
        self.set_state(f"ENGAGED by {source}: {reason}" if engaged else "released")
        if engaged:  # one logging call per severity: rclpy fixes a call site's severity
            self.get_logger().warn(f"e-stop ENGAGED by {source}: {reason}")
        else:
            self.get_logger().info(f"e-stop released ({source})")

    def on_engage(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        reason = "operator request" if request.data else ""
        self.publish_estop(request.data, reason, "operator")
        response.success = True
        response.message = "e-stop engaged" if request.data else "e-stop released"
        return response

    def on_scan(self, msg: LaserScan) -> None:
        nearest = min(msg.ranges) if msg.ranges else math.inf
        if nearest < self.stop_distance and not self.engaged:
            self.publish_estop(True, f"obstacle closer than {self.stop_distance:.2f} m", "safety_monitor")


# ---------------------------------------------------------------------------------- navigation
@dataclass
class _Drive:
    goal_handle: object
    target: tuple[float, float]
    speed: float
    start_distance: float
    last_pose: tuple[float, float]
    done: Future
    travelled: float = 0.0


class Navigator(RobotNode):
    """Action server ``navigate``: drives the base to a point with feedback, cancel and e-stop abort.

    The control loop is a 20 Hz timer; the execute callback is a coroutine that awaits
    the loop's verdict, so one single-threaded executor runs everything.
    """

    def __init__(self, namespace: str = ""):
        super().__init__("navigator", namespace)
        self.max_speed = self.declare_parameter("max_speed", 1.5).value  # [m/s]
        self.tolerance = self.declare_parameter("goal_tolerance", 0.05).value  # [m]
        self.add_on_set_parameters_callback(self.check_parameters)
        self.pose: tuple[float, float] | None = None
        self.active: _Drive | None = None
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
        drive = _Drive(goal_handle, target, goal_handle.request.speed, max(distance, 1e-6),
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
            self.finish("succeeded")
            return
        cruise = min(drive.speed if drive.speed > 0 else self.max_speed, self.max_speed)
        speed = max(0.05, min(cruise, 2.0 * remaining))  # slow down over the last metre
        self.cmd_publisher.publish(Twist(linear=_vector(speed * dx / remaining, speed * dy / remaining)))
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


def _vector(x: float, y: float):
    from geometry_msgs.msg import Vector3

    return Vector3(x=float(x), y=float(y), z=0.0)


class Gripper(RobotNode):
    """Service ``pick_item``: succeeds when the robot stands at the shelf and the e-stop is released."""

    def __init__(self, namespace: str = "", reach: float = 0.25):
        super().__init__("gripper", namespace)
        self.reach = self.declare_parameter("reach", reach).value  # [m]
        self.pose: tuple[float, float] | None = None
        self.holding = ""
        self.odom_subscription = self.create_subscription(Odometry, "odom", self.on_odom, ODOM_QOS)
        self.service = self.create_service(PickItem, "pick_item", self.on_pick)
        self.set_state("ready")

    def on_odom(self, msg: Odometry) -> None:
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y)

    def on_pick(self, request: PickItem.Request, response: PickItem.Response) -> PickItem.Response:
        shelf = SHELVES.get(request.shelf)
        if self.estop_engaged:
            response.success, response.message = False, "e-stop engaged: the gripper is locked"
        elif shelf is None:
            response.success = False
            response.message = f"unknown shelf {request.shelf!r}; shelves: {', '.join(sorted(SHELVES))}"
        elif self.pose is None or math.dist(self.pose, shelf) > self.reach:
            away = math.dist(self.pose, shelf) if self.pose else math.inf
            response.success = False
            response.message = f"not at shelf {request.shelf}: {away:.2f} m away (reach {self.reach} m)"
        else:
            self.holding = request.item_id
            response.success, response.message = True, f"picked {request.item_id} from {request.shelf}"
            self.set_state(f"holding {request.item_id}")
        return response

    def on_estop(self, msg: EStop) -> None:
        if msg.engaged:
            self.set_state("locked (e-stop)")
        else:
            self.set_state(f"holding {self.holding}" if self.holding else "ready")


class StatusLight(RobotNode):
    """A beacon on the robot: green, or red while the e-stop is engaged (the late joiner)."""

    def __init__(self, namespace: str = ""):
        super().__init__("status_light", namespace)
        self.set_state("amber (e-stop state unknown)")

    def on_estop(self, msg: EStop) -> None:
        self.set_state(f"RED: {msg.source} e-stop" if msg.engaged else "green")


# ---------------------------------------------------------------------------------- missions
@dataclass
class Mission:
    """A pick mission: drive to the shelf, pick, drive home. Filled in by :class:`MissionRunner`."""

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


_LEGS = {"to_shelf": (0.0, 0.45), "home": (0.55, 1.0)}


class MissionRunner(RobotNode):
    """Runs pick missions with the navigator (action) and the gripper (service).

    ``start(item_id, shelf)`` returns a :class:`Mission` at once; the mission runs as a
    coroutine in the executor and reports progress from the action's feedback.
    """

    def __init__(self, namespace: str = "", home: list[float] | None = None):
        super().__init__("mission_runner", namespace)
        robot = namespace.strip("/").split("/")[-1] if namespace.strip("/") else "robot1"
        self.home = tuple(home or HOMES.get(robot, (0.0, 0.0)))
        self.navigate = ActionClient(self, Navigate, "navigate")
        self.pick = self.create_client(PickItem, "pick_item")
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
        if not self.pick.wait_for_service(timeout_sec=timeout):
            raise CourseError(f"no pick_item service under {self.get_namespace()} after {timeout:g} s")
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
        self.end(mission, True, f"delivered {mission.item_id}")

    async def drive(self, mission: Mission, point, leg: str) -> bool:
        low, high = _LEGS[leg]

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


def mission_progress(mission: Mission):
    """A progress bar widget that follows a mission's action feedback (chapter 10)."""
    import ipywidgets as widgets

    bar = widgets.FloatProgress(value=mission.progress, min=0.0, max=1.0,
                                description=f"{mission.item_id}", bar_style="info",
                                layout=widgets.Layout(width="420px"))
    label = widgets.Label(value=mission.state)

    def follow(m: Mission) -> None:
        bar.value = m.progress
        label.value = m.state
        if m.finished:
            bar.bar_style = "success" if m.success else "danger"

    mission.listeners.append(follow)
    follow(mission)
    return _labelled_box([bar, label], f"progress of mission {mission.item_id}@{mission.shelf}")


def _labelled_box(children, text: str):
    """An HBox whose plain-text form is a fixed label (notebook outputs stay comparable)."""
    import ipywidgets as widgets

    class LabelledBox(widgets.HBox):
        def __repr__(self) -> str:
            return f"<{text}>"

    return LabelledBox(children)


# ---------------------------------------------------------------------------------- a whole robot
def make_robot_drivers(namespace: str = "/robot1", camera_hz: float = 30.0,
                       home: list[float] | None = None, camera: bool = True) -> list[Node]:
    """Child-process target: the robot's own computer (camera, lidar, base, safety monitor)."""
    robot = namespace.strip("/").split("/")[-1]
    home = list(home or HOMES.get(robot, (0.0, 0.0)))
    nodes: list[Node] = [SafetyMonitor(namespace), BaseController(namespace, home),
                         LidarDriver(namespace, home=home)]
    if camera:
        nodes.append(CameraDriver(namespace, rate_hz=camera_hz))
    return nodes


@dataclass
class Robot:
    """Handle of a started robot: its namespace, driver process and the kernel's nodes."""

    namespace: str
    drivers: object
    navigator: Navigator
    gripper: Gripper

    def node_names(self) -> list[str]:
        names = ["base", "camera", "gripper", "lidar", "navigator", "safety_monitor"]
        return [full_name(self.namespace, n) for n in names]


def start_robot(rt, name: str = "robot1", camera: bool = True, camera_hz: float = 30.0) -> Robot:
    """Start a robot: its drivers in a child process (labelled ``name``), navigator and gripper here.

    Re-running replaces the child process and the kernel's nodes of that robot.
    """
    namespace = f"/{name}"
    home = list(HOMES.get(name, (0.0, 0.0)))
    drivers = rt.spawn(name, "course_helpers.chapters.ch10_capstone.capstone:make_robot_drivers",
                       params={"namespace": namespace, "camera_hz": camera_hz, "home": home,
                               "camera": camera},
                       wait_for=full_name(namespace, "safety_monitor"), timeout=20.0)
    navigator = rt.add(Navigator, namespace, console=False)
    gripper = rt.add(Gripper, namespace, console=False)
    rt.wait_until(lambda: navigator.pose is not None and not navigator.estop_engaged, 10.0,
                  f"{namespace}/navigator to hear odometry and the released e-stop")
    # Wait until discovery has reported every endpoint of the robot, so that the graph,
    # the QoS table and the tools show the whole robot from the first look.
    publishers = {"estop": 1, "odom": 1, "scan": 1, "cmd_vel": 1}
    subscribers = {"estop": 5 if camera else 4, "odom": 3, "scan": 1, "cmd_vel": 1}
    if camera:
        publishers[CAMERA_TOPIC] = 1

    def discovered() -> bool:
        graph = rt.graph
        return (all(graph.count_publishers(full_name(namespace, t)) >= n for t, n in publishers.items())
                and all(graph.count_subscribers(full_name(namespace, t)) >= n
                        for t, n in subscribers.items()))

    rt.wait_until(discovered, 10.0, f"every endpoint of {namespace} in the graph")
    return Robot(namespace, drivers, navigator, gripper)


class EStopButton(Node):
    """The operator's e-stop button: a client of ``safety_monitor/engage`` (std_srvs/SetBool).

    ``press()`` and ``release()`` block until the safety monitor answers. The client is
    created once, with the node, so that discovery has matched it before the first call.
    """

    def __init__(self, namespace: str = "/robot1"):
        super().__init__("estop_button", namespace=namespace)
        self.client = self.create_client(SetBool, "safety_monitor/engage")

    def press(self, timeout: float = 5.0) -> str:
        """Engage the e-stop; returns the safety monitor's answer."""
        return self._call(True, timeout)

    def release(self, timeout: float = 5.0) -> str:
        """Release the e-stop; returns the safety monitor's answer."""
        return self._call(False, timeout)

    def _call(self, engaged: bool, timeout: float) -> str:
        if not self.client.wait_for_service(timeout_sec=timeout):
            raise CourseError(f"no safety monitor under {self.get_namespace()} (is the robot started?)")
        for _attempt in range(3):  # a reply can be lost if it races the client's discovery
            answered = threading.Event()
            future = self.client.call_async(SetBool.Request(data=engaged))
            future.add_done_callback(lambda _f, answered=answered: answered.set())
            if answered.wait(timeout / 3):
                return future.result().message
            self.client.remove_pending_request(future)
        raise CourseError(f"the safety monitor under {self.get_namespace()} did not answer "
                          f"within {timeout:g} s")


# ---------------------------------------------------------------------------------- node states
class StateBoard(Node):
    """Collects the latched ``~/_state`` of every node under a namespace into a table."""

    def __init__(self, watch: str = "/", name: str = "state_board"):
        super().__init__(name)
        self.watch = watch.rstrip("/") + "/"
        self.states: dict[str, str] = {}
        self.subscriptions_by_topic: dict[str, object] = {}

    def refresh(self) -> None:
        """Subscribe to state topics that appeared since the last call (run in the executor)."""
        for topic, types in self.get_topic_names_and_types():
            if (topic.endswith("/_state") and topic.startswith(self.watch)
                    and "std_msgs/msg/String" in types and topic not in self.subscriptions_by_topic):
                node = topic[: -len("/_state")]
                self.subscriptions_by_topic[topic] = self.create_subscription(
                    String, topic, lambda msg, node=node: self.states.__setitem__(node, msg.data),
                    LATCHED_QOS)

    def table(self, nodes: list[str] | None = None) -> str:
        """The current states as an aligned table, sorted by node name."""
        names = nodes if nodes is not None else list(self.states)
        return state_table({n: self.states.get(n, "(no state yet)") for n in names})


def state_table(*columns: dict[str, str], titles: tuple[str, ...] = ("state",)) -> str:
    """Aligned table of one or more {node: state} snapshots (e.g. before and after), sorted by node."""
    if len(titles) != len(columns):
        titles = tuple(f"state {i + 1}" for i in range(len(columns)))
    names = sorted(set().union(*columns))
    widths = [max([len(n) for n in names] + [4])]
    widths += [max([len(c.get(n, "")) for n in names] + [len(t)]) for c, t in zip(columns, titles,
                                                                                 strict=True)]
    header = ["node", *titles]
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True)).rstrip(),
             "  ".join("-" * w for w in widths)]
    for name in names:
        row = [name, *[c.get(name, "") for c in columns]]
        lines.append("  ".join(v.ljust(w) for v, w in zip(row, widths, strict=True)).rstrip())
    return "\n".join(lines)


def collect_states(rt, board: StateBoard, nodes: list[str], until: Callable[[dict], bool] | None = None,
                   timeout: float = 5.0) -> dict[str, str]:
    """Refresh ``board`` until it has a state for every node in ``nodes`` (and ``until(states)``)."""
    def ready() -> bool:
        rt.call_in_executor(board.refresh)
        have = all(n in board.states for n in nodes)
        return have and (until is None or until(dict(board.states)))

    rt.wait_until(ready, timeout, f"the states of {', '.join(nodes)}")
    return {n: board.states[n] for n in sorted(nodes)}


# ---------------------------------------------------------------------------------- perception
def detect_marker_python(data: bytes, width: int, height: int, smoothing: int = 5,
                         threshold: int = 200) -> tuple[float, float, int]:
    """Find the bright item tag: box-filter each pixel over (2*smoothing+1)^2 pixels, threshold,
    average the positions. Pure Python, one pixel at a time (the prototype)."""
    size = 2 * smoothing + 1
    limit = threshold * size * size
    sum_x = sum_y = count = 0
    for y in range(smoothing, height - smoothing):
        for x in range(smoothing, width - smoothing):
            total = 0
            for dy in range(-smoothing, smoothing + 1):
                row = (y + dy) * width + x
                for dx in range(-smoothing, smoothing + 1):
                    total += data[row + dx]
            if total >= limit:
                sum_x += x
                sum_y += y
                count += 1
    return (sum_x / count, sum_y / count, count) if count else (0.0, 0.0, 0)


def detect_marker_numpy(data: bytes, width: int, height: int, smoothing: int = 5,
                        threshold: int = 200) -> tuple[float, float, int]:
    """The same detector on whole arrays: a box filter from an integral image (same result)."""
    image = np.frombuffer(data, dtype=np.uint8).reshape(height, width)
    integral = np.pad(image.astype(np.int64).cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    size = 2 * smoothing + 1
    box = (integral[size:, size:] - integral[:-size, size:]
           - integral[size:, :-size] + integral[:-size, :-size])
    ys, xs = np.nonzero(box >= threshold * size * size)
    if len(xs) == 0:
        return (0.0, 0.0, 0)
    return (float(xs.mean()) + smoothing, float(ys.mean()) + smoothing, int(len(xs)))


DETECTORS = {"python": detect_marker_python, "numpy": detect_marker_numpy}


class Perception(RobotNode):
    """Detects the item tag in every camera frame and publishes ``perception/detections``.

    ``detector`` picks the implementation ('python' or 'numpy'); ``depth`` is the
    subscription's history depth; ``reliable`` asks for RELIABLE delivery.
    """

    def __init__(self, namespace: str = "", detector: str = "python", depth: int = 1,
                 reliable: bool = False):
        if detector not in DETECTORS:
            raise CourseError(f"detector must be one of {sorted(DETECTORS)}, got {detector!r}")
        super().__init__("perception", namespace)
        self.detect = DETECTORS[detector]
        reliability = ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT
        qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=reliability,
                         durability=DurabilityPolicy.VOLATILE)
        self.subscription = self.create_subscription(Image, CAMERA_TOPIC, self.on_frame, qos)
        self.publisher = self.create_publisher(PointStamped, DETECTIONS_TOPIC, 10)
        self.set_state(f"detecting ({detector}, depth {depth})")

    def on_frame(self, msg: Image) -> None:
        x, y, pixels = self.detect(bytes(msg.data), msg.width, msg.height)
        out = PointStamped()
        out.header = msg.header  # keep the camera's stamp: the receiver can measure gaps and age
        out.point.x, out.point.y, out.point.z = float(x), float(y), float(pixels)
        self.publisher.publish(out)


def make_perception(namespace: str = "/robot1", detector: str = "python", depth: int = 1,
                    reliable: bool = False) -> Perception:
    """Child-process target: a :class:`Perception` node."""
    return Perception(namespace, detector=detector, depth=depth, reliable=reliable)


def time_detector(detector: Callable, repeats: int = 3) -> float:
    """Mean time [ms] ``detector`` takes on one camera frame."""
    frame = make_frame(0)
    height, width = frame.shape
    data = frame.tobytes()
    started = time.perf_counter()
    for _ in range(repeats):
        detector(data, width, height)
    return (time.perf_counter() - started) / repeats * 1000.0


@dataclass
class Delivery:
    """What arrived on a stamped topic during a measurement."""

    topic: str
    expected_hz: float
    seconds: float
    received: int
    missed: int
    mean_age_ms: float

    @property
    def delivered_hz(self) -> float:
        return self.received / self.seconds if self.seconds else 0.0

    @property
    def missed_fraction(self) -> float:
        total = self.received + self.missed
        return self.missed / total if total else 1.0

    def __str__(self) -> str:
        return (f"{self.topic}: {self.delivered_hz:.1f} Hz delivered of {self.expected_hz:g} Hz, "
                f"{self.missed_fraction:.0%} of frames missed, mean age {self.mean_age_ms:.0f} ms")


def measure_delivery(rt, topic: str, msg_type=PointStamped, seconds: float = 3.0,
                     expected_hz: float = 30.0, qos: QoSProfile | int = 50,
                     first_timeout: float = 8.0) -> Delivery:
    """Count messages on ``topic`` for ``seconds``; find missed frames from gaps in header stamps.

    A gap of k frame periods between consecutive stamps means k - 1 frames never made it.
    The age is receive time minus the camera's stamp (same machine, same clock). If
    nothing arrives within ``first_timeout`` s, the result says 0 messages (all missed). The
    default leaves room for a just-spawned process to start, be discovered and send (a busy
    CI machine once needed more than 3 s).
    """
    stamps: list[float] = []
    ages: list[float] = []

    def on_message(msg) -> None:
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        stamps.append(stamp)
        ages.append(time.time() - stamp)

    sub = rt.graph.create_subscription(msg_type, topic, on_message, qos)
    try:
        try:
            rt.wait_until(lambda: len(stamps) > 0, first_timeout, f"a first message on {topic}")
        except WaitTimeout:
            return Delivery(topic, expected_hz, first_timeout, 0, round(first_timeout * expected_hz),
                            float("nan"))
        time.sleep(0.3)  # let the pipeline settle
        stamps.clear()
        ages.clear()
        started = time.monotonic()
        time.sleep(seconds)
        elapsed = time.monotonic() - started
        got = sorted(stamps)
        age = list(ages)
    finally:
        rt.call_in_executor(rt.graph.destroy_subscription, sub)
    period = 1.0 / expected_hz
    missed = sum(max(0, round((b - a) / period) - 1) for a, b in zip(got, got[1:], strict=False))
    return Delivery(topic, expected_hz, elapsed, len(got), missed,
                    1000.0 * sum(age) / len(age) if age else float("nan"))


# ---------------------------------------------------------------------------------- QoS from the graph
_RELIABILITY = {ReliabilityPolicy.RELIABLE: "reliable", ReliabilityPolicy.BEST_EFFORT: "best_effort"}
_DURABILITY = {DurabilityPolicy.VOLATILE: "volatile", DurabilityPolicy.TRANSIENT_LOCAL: "transient_local"}


def endpoint_qos(rt, topic: str) -> dict[str, list[tuple[str, str, str]]]:
    """Publishers and subscriptions of ``topic``: (node, reliability, durability), sorted.

    The history depth is not in the list: it is a local setting of each endpoint and is
    not exchanged during discovery (``ros2 topic info -v`` shows it as UNKNOWN).
    """
    def rows(infos):
        return sorted((full_name(i.node_namespace, i.node_name),
                       _RELIABILITY.get(i.qos_profile.reliability, str(i.qos_profile.reliability)),
                       _DURABILITY.get(i.qos_profile.durability, str(i.qos_profile.durability)))
                      for i in infos)

    return {"publishers": rows(rt.graph.get_publishers_info_by_topic(topic)),
            "subscriptions": rows(rt.graph.get_subscriptions_info_by_topic(topic))}


def qos_table(rt, namespace: str, topics: list[str]) -> str:
    """A table of who publishes and subscribes each topic under ``namespace``, with their QoS."""
    lines = [f"{'topic':<26} {'endpoint':<10} {'node':<28} {'reliability':<12} durability"]
    for topic in topics:
        full = topic if topic.startswith("/") else full_name(namespace, topic)
        info = endpoint_qos(rt, full)
        for kind, label in (("publishers", "pub"), ("subscriptions", "sub")):
            for node, reliability, durability in info[kind]:
                if node.startswith("/_") or "/_" in node:
                    continue  # the runtime's own hidden node
                lines.append(f"{full:<26} {label:<10} {node:<28} {reliability:<12} {durability}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------- fleets and domains
def nodes_in_domain(domain_id: int, expect: list[str] | None = None, timeout: float = 8.0,
                    settle_s: float = 1.0) -> list[str]:
    """Look into another ROS domain with a temporary context: the node names found there, sorted.

    Waits until every name in ``expect`` is seen (or ``timeout``), else for ``settle_s``.
    """
    context = Context()
    rclpy.init(context=context, domain_id=int(domain_id), signal_handler_options=SignalHandlerOptions.NO)
    try:
        probe = Node("_domain_probe", context=context, enable_rosout=False,
                     start_parameter_services=False)
        deadline = time.monotonic() + (timeout if expect else settle_s)
        names: set[str] = set()
        while time.monotonic() < deadline:
            names = {full_name(ns, n) for n, ns in probe.get_node_names_and_namespaces()
                     if not n.startswith("_")}
            if expect and set(expect) <= names:
                break
            time.sleep(0.1)
        probe.destroy_node()
        return sorted(names)
    finally:
        context.try_shutdown()


_spare_domain: int | None = None


def spare_domain() -> int:
    """A second ROS domain that no other course kernel on this machine uses (for a fleet demo).

    Reserved once per process, with the same lock files as the runtime's own domain.
    """
    global _spare_domain
    if _spare_domain is None:
        from course_helpers.core.domains import reserve_domain

        _spare_domain = reserve_domain()
    return _spare_domain


# ---------------------------------------------------------------------------------- plots
def plot_deliveries(results: dict[str, Delivery]):
    """Bar charts of delivered rate and missed frames per configuration; returns the Figure."""
    import matplotlib.pyplot as plt

    labels = list(results)
    rates = [results[k].delivered_hz for k in labels]
    missed = [100.0 * results[k].missed_fraction for k in labels]
    expected = max(r.expected_hz for r in results.values())
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.6))
    colours = ["#cf222e" if m > 10 else "#1a7f37" for m in missed]
    left.barh(labels, rates, color=colours)
    left.axvline(expected, color="#333333", linestyle="--", linewidth=1)
    left.text(expected, len(labels) - 0.5, f" camera {expected:g} Hz", va="center", fontsize=8)
    left.set_xlabel("frames processed by perception [Hz]")
    left.set_xlim(0, expected * 1.3)
    left.invert_yaxis()
    right.barh(labels, missed, color=colours)
    right.set_xlabel("frames missed [%]")
    right.set_xlim(0, 100)
    right.invert_yaxis()
    right.set_yticklabels([])
    fig.suptitle("Perception of a 30 Hz camera: what arrives where it is needed")
    fig.tight_layout()
    return fig
