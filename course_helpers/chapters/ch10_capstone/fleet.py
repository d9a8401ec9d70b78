"""Starting robots: one robot's drivers in a child process and its planning nodes in the kernel.

Several robots share one domain under their own namespaces (``/robot1``, ``/robot2``);
:class:`EStopButton` is the operator's button for one of them, :class:`FleetManager` the
console that stops (and releases) every robot of the fleet at once.
"""

from __future__ import annotations

from dataclasses import dataclass

from course_interfaces.msg import EStop
from rclpy.node import Node
from std_srvs.srv import SetBool

from course_helpers.chapters.ch10_capstone.channels import CAMERA_TOPIC, ESTOP_QOS, FLEET_ESTOP_TOPIC
from course_helpers.chapters.ch10_capstone.navigator import Navigator
from course_helpers.chapters.ch10_capstone.robot import Gripper, make_robot_drivers
from course_helpers.chapters.ch10_capstone.warehouse import home_of
from course_helpers.core.errors import CourseError
from course_helpers.core.names import full_name
from course_helpers.core.processes import ChildProcess
from course_helpers.core.waiting import poll_until


@dataclass
class Robot:
    """Handle of a started robot: its namespace, driver process and the kernel's nodes."""

    namespace: str
    drivers: ChildProcess
    navigator: Navigator
    gripper: Gripper

    def node_names(self) -> list[str]:
        """Full names of the robot's own nodes (drivers, navigator, gripper), sorted."""
        names = ["base", "camera", "gripper", "lidar", "navigator", "safety_monitor"]
        return [full_name(self.namespace, n) for n in names]


def start_robot(rt, name: str = "robot1", camera: bool = True, camera_hz: float = 30.0,
                safety_monitor: bool = True) -> Robot:
    """Start a robot: its drivers in a child process (labelled ``name``), navigator and gripper here.

    Args: ``rt`` the kernel's runtime, ``name`` the robot ('robot1' -> namespace /robot1, its
    dock from the warehouse map), ``camera`` False leaves the camera out (less CPU),
    ``camera_hz`` the camera's rate [Hz], ``safety_monitor`` False starts the robot without
    one (add your own: ``rt.add(MyMonitor, '/robot1')``; until it publishes a released e-stop,
    the robot stays stopped).
    Returns: a :class:`Robot` once the navigator and the gripper hear odometry and discovery shows
    every endpoint of the robot (its topics and, with its safety monitor, the ``engage`` service),
    and with its safety monitor, once both hear the released e-stop. Re-running
    replaces the child process and the kernel's nodes of that robot.
    """
    return start_robots(rt, [name], camera=camera, camera_hz=camera_hz, safety_monitor=safety_monitor)[0]


def start_robots(rt, names: list[str], camera: bool = True, camera_hz: float = 30.0,
                 safety_monitor: bool = True) -> list[Robot]:
    """Start several robots like :func:`start_robot`; their driver processes start together.

    Returns: one :class:`Robot` per name, in order.
    """
    children = [rt.spawn(name, make_robot_drivers,
                         params={"namespace": f"/{name}", "camera_hz": camera_hz, "home": list(home_of(name)),
                                 "camera": camera, "safety_monitor": safety_monitor})
                for name in names]
    return [_join(rt, f"/{name}", drivers, camera, safety_monitor)
            for name, drivers in zip(names, children, strict=True)]


def _join(rt, namespace: str, drivers: ChildProcess, camera: bool, safety_monitor: bool) -> Robot:
    """Wait for a robot's driver process, add its navigator and gripper, and wait for its endpoints."""
    drivers.wait_for_report("ready", 20.0, f"the drivers of {namespace} to be created")
    rt.wait_for_child_node(drivers, full_name(namespace, "lidar"), 20.0)
    navigator = rt.add(Navigator, namespace, console=False)
    gripper = rt.add(Gripper, namespace, console=False)
    # Both read odometry from the drivers' process: on a busy machine a lost discovery message can
    # keep one of them unmatched for seconds, and a gripper that never heard odometry cannot pick.
    rt.wait_until(lambda: navigator.pose is not None and gripper.pose is not None, 10.0,
                  f"{namespace}/navigator and {namespace}/gripper to hear odometry")
    if safety_monitor:
        rt.wait_until(lambda: not navigator.estop_engaged and not gripper.estop_engaged, 10.0,
                      f"{namespace}/navigator and {namespace}/gripper to hear the released e-stop")
    # Wait until discovery has reported every endpoint of the robot, so that the graph,
    # the QoS table and the tools show the whole robot from the first look.
    publishers = {"odom": 1, "scan": 1, "cmd_vel": 1}
    subscribers = {"estop": 5 if camera else 4, "odom": 3, "cmd_vel": 1}
    if safety_monitor:
        publishers["estop"] = 1
        subscribers["scan"] = 1
    if camera:
        publishers[CAMERA_TOPIC] = 1
    services = {full_name(namespace, "safety_monitor/engage")} if safety_monitor else set()

    def discovered() -> bool:
        graph = rt.graph
        return (all(graph.count_publishers(full_name(namespace, t)) >= n for t, n in publishers.items())
                and all(graph.count_subscribers(full_name(namespace, t)) >= n
                        for t, n in subscribers.items())
                and services <= {name for name, _types in graph.get_service_names_and_types()})

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
            future = self.client.call_async(SetBool.Request(data=engaged))
            if poll_until(future.done, timeout / 3):
                return future.result().message
            self.client.remove_pending_request(future)
        raise CourseError(f"the safety monitor under {self.get_namespace()} did not answer "
                          f"within {timeout:g} s")


class FleetManager(Node):
    """The fleet's console: one e-stop for every robot, on the absolute topic ``/fleet/estop``.

    Latched like a robot's own e-stop (RELIABLE + TRANSIENT_LOCAL, depth 1), so a robot that
    starts later still learns the fleet's current state. ``stop(reason)`` engages it, ``release()``
    releases it.
    """

    def __init__(self):
        super().__init__("fleet_manager")
        self.publisher = self.create_publisher(EStop, FLEET_ESTOP_TOPIC, ESTOP_QOS)

    def stop(self, reason: str = "fleet stop") -> None:
        self.publisher.publish(EStop(engaged=True, reason=reason, source="fleet_manager"))

    def release(self) -> None:
        self.publisher.publish(EStop(engaged=False, reason="", source="fleet_manager"))
