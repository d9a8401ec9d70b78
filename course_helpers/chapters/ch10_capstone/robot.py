"""The warehouse robot's nodes: small ``Node`` subclasses that follow the e-stop.

============== ================================================ =============================
node           does                                             runs
============== ================================================ =============================
camera         30 Hz ``camera/image_raw`` (sensor_msgs/Image)   child process (the robot)
lidar          10 Hz ``scan`` (sensor_msgs/LaserScan)           child process (the robot)
base           ``cmd_vel`` in, ``odom`` out (nav_msgs)          child process (the robot)
safety_monitor ``estop`` (RELIABLE + TRANSIENT_LOCAL)           child process (the robot)
gripper        services ``pick_item``, ``place_item``           kernel
status_light   follows the e-stop (the late joiner)             kernel
perception     ``camera/image_raw`` -> ``perception/...``       child process (section 8)
============== ================================================ =============================

The navigator is in :mod:`.navigator`, the mission runner in :mod:`.missions`. The notebook
prints each class's source before the robot runs, so what a student reads is what runs.

Every node subscribes to ``estop`` with the e-stop QoS (so a node that starts late learns
the current state at once), treats an unknown state as engaged (fail safe), and publishes
what it is doing on its latched ``~/_state`` topic, which :class:`.states.StateBoard`
collects into a table. The leading underscore hides that topic, like other infrastructure,
from the graph view and ``%ros2 topic list``; ``%ros2 topic echo /robot1/base/_state``
still shows it.
"""

from __future__ import annotations

import math
import time

import numpy as np
from course_interfaces.msg import EStop
from course_interfaces.srv import PickItem
from geometry_msgs.msg import PointStamped, Twist
from nav_msgs.msg import Odometry
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Image, LaserScan
from std_msgs.msg import Float64, String
from std_srvs.srv import SetBool, Trigger

from course_helpers.chapters.ch10_capstone.channels import (
    CAMERA_TOPIC,
    COMMAND_QOS,
    DETECTIONS_TOPIC,
    ESTOP_QOS,
    LATCHED_QOS,
    ODOM_QOS,
    PROCESSING_TIME_TOPIC,
    SENSOR_QOS,
    STATE_TOPIC,
)
from course_helpers.chapters.ch10_capstone.detectors import DETECTORS
from course_helpers.chapters.ch10_capstone.warehouse import (
    SHELVES,
    SPEED_LIMIT,
    cast_rays,
    home_of,
    make_frame,
)
from course_helpers.core.errors import CourseError


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
        """The ``obstacles`` parameter as (x, y, radius) circles [m]; none while it is unset."""
        try:
            values = list(self.get_parameter("obstacles").value or [])
        except ParameterUninitializedException:  # declared without a value: no obstacles
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
    ``self.current`` is the e-stop message it published last (the robot's current state).
    """

    def __init__(self, namespace: str = ""):
        super().__init__("safety_monitor", namespace, follow_estop=False)
        self.stop_distance = self.declare_parameter("stop_distance", 0.4).value  # [m]
        self.publisher = self.create_publisher(EStop, "estop", ESTOP_QOS)
        self.engage_service = self.create_service(SetBool, "~/engage", self.on_engage)
        self.scan_subscription = self.create_subscription(LaserScan, "scan", self.on_scan, SENSOR_QOS)
        self.publish_estop(False, "", "safety_monitor")  # latched: everyone learns "released"

    def publish_estop(self, engaged: bool, reason: str, source: str) -> None:
        """Publish the robot's e-stop state: ``engaged``, why, and who decided it."""
        self.current = EStop(engaged=engaged, reason=reason, source=source)
        self.publisher.publish(self.current)
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
        if nearest < self.stop_distance and not self.current.engaged:
            self.publish_estop(True, f"obstacle closer than {self.stop_distance:.2f} m", "safety_monitor")


class Gripper(RobotNode):
    """Service ``pick_item``: succeeds when the robot stands at the shelf and the e-stop is released.

    Service ``place_item`` (std_srvs/Trigger) sets the item it holds down where the robot
    stands (the mission runner calls it at the dock), so the gripper is empty again.
    """

    def __init__(self, namespace: str = "", reach: float = 0.25):
        super().__init__("gripper", namespace)
        self.reach = self.declare_parameter("reach", reach).value  # [m]
        self.pose: tuple[float, float] | None = None
        self.holding = ""
        self.odom_subscription = self.create_subscription(Odometry, "odom", self.on_odom, ODOM_QOS)
        self.service = self.create_service(PickItem, "pick_item", self.on_pick)
        self.place_service = self.create_service(Trigger, "place_item", self.on_place)
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

    def on_place(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        if self.estop_engaged:
            response.success, response.message = False, "e-stop engaged: the gripper is locked"
        elif not self.holding:
            response.success, response.message = False, "nothing to place: the gripper is empty"
        else:
            response.success, response.message = True, f"placed {self.holding}"
            self.holding = ""
            self.set_state("ready")
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


class Perception(RobotNode):
    """Detects the item tag in every camera frame and publishes ``perception/detections``.

    ``detector`` picks the implementation ('python' or 'numpy'); ``depth`` is the
    subscription's history depth; ``reliable`` asks for RELIABLE delivery. After each frame it
    publishes how long the frame took on ``~/processing_time_ms``.
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
        self.timing_publisher = self.create_publisher(Float64, PROCESSING_TIME_TOPIC, 10)
        self.set_state(f"detecting ({detector}, depth {depth})")

    def on_frame(self, msg: Image) -> None:
        started = time.perf_counter()
        x, y, pixels = self.detect(bytes(msg.data), msg.width, msg.height)
        out = PointStamped()
        out.header = msg.header  # keep the camera's stamp: the receiver can measure gaps and age
        out.point.x, out.point.y, out.point.z = float(x), float(y), float(pixels)
        self.publisher.publish(out)
        # the node's own stopwatch: how long this frame took, for anyone diagnosing it [ms]
        self.timing_publisher.publish(Float64(data=1000.0 * (time.perf_counter() - started)))


def make_robot_drivers(namespace: str = "/robot1", camera_hz: float = 30.0,
                       home: list[float] | None = None, camera: bool = True,
                       safety_monitor: bool = True) -> list[Node]:
    """The robot's own computer, as a child-process target: ``rt.spawn('robot1', make_robot_drivers)``.

    Args: ``namespace`` of the robot, ``camera_hz`` the camera's rate [Hz], ``home`` its start
    position [x, y] in metres (default: its dock), ``camera`` False leaves the camera out,
    ``safety_monitor`` False leaves the safety monitor out (one of your own runs elsewhere).
    Returns: the safety monitor, base, LIDAR and camera nodes, which the child spins.
    """
    home = list(home or home_of(namespace))
    nodes: list[Node] = [BaseController(namespace, home), LidarDriver(namespace, home=home)]
    if safety_monitor:
        nodes.insert(0, SafetyMonitor(namespace))
    if camera:
        nodes.append(CameraDriver(namespace, rate_hz=camera_hz))
    return nodes
