"""Reference solutions of chapter 06 (parameters); CI checks them with ``checks.ch06_parameters``."""

from __future__ import annotations

from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from std_msgs.msg import Float64, String


class OverheatMonitor(Node):
    """Exercise 06: classifies the latest temperature as ok / warning / critical, at a tunable rate."""

    def __init__(self, **kwargs):
        super().__init__('overheat_monitor', **kwargs)  # kwargs: parameter_overrides, cli_args, ...
        self.declare_parameter('status_topic', 'overheat_status', ParameterDescriptor(
            description='where the status strings go (fixed at start)', read_only=True))
        self.declare_parameter('rate_hz', 5.0, ParameterDescriptor(
            description='status publish rate [Hz]',
            floating_point_range=[FloatingPointRange(from_value=1.0, to_value=20.0, step=0.0)]))
        self.declare_parameter('warning_c', 60.0, ParameterDescriptor(description='warning threshold [°C]'))
        self.declare_parameter('critical_c', 80.0, ParameterDescriptor(description='critical threshold [°C]'))
        self.add_on_set_parameters_callback(self.validate)
        self.add_post_set_parameters_callback(self.apply)

        self.temperature = None  # latest reading [°C]
        self.publisher = self.create_publisher(String, self.get_parameter('status_topic').value, 10)
        self.subscription = self.create_subscription(Float64, 'temperature', self.on_temperature, 10)
        self.timer = self.create_timer(1.0 / self.get_parameter('rate_hz').value, self.publish_status)

    def validate(self, parameters) -> SetParametersResult:
        """Reject a change that would put warning_c at or above critical_c."""
        thresholds = {name: self.get_parameter(name).value for name in ('warning_c', 'critical_c')}
        for parameter in parameters:
            if parameter.name in thresholds:
                thresholds[parameter.name] = parameter.value
        if thresholds['warning_c'] >= thresholds['critical_c']:
            return SetParametersResult(successful=False, reason=(
                f"warning_c ({thresholds['warning_c']}) must be below critical_c "
                f"({thresholds['critical_c']})"))
        return SetParametersResult(successful=True)

    def apply(self, parameters) -> None:
        """After a successful change: retune the timer if rate_hz changed."""
        for parameter in parameters:
            if parameter.name == 'rate_hz':
                self.timer.timer_period_ns = int(1e9 / parameter.value)  # period [ns]

    def on_temperature(self, msg: Float64) -> None:
        self.temperature = msg.data

    def publish_status(self) -> None:
        if self.temperature is None:
            status = 'no data'
        elif self.temperature >= self.get_parameter('critical_c').value:
            status = 'critical'
        elif self.temperature >= self.get_parameter('warning_c').value:
            status = 'warning'
        else:
            status = 'ok'
        self.publisher.publish(String(data=status))


def conveyor_launch():
    """Exercise 06b, the launch description: the belt sensor and the counter of line 1, configured."""
    from course_helpers.chapters.ch06_parameters import NodeLaunch

    return [
        NodeLaunch('talker', 'belt_sensor', namespace='/line1',
                   parameters={'topic': 'items', 'rate_hz': 10.0, 'message': 'item'}),
        NodeLaunch('listener', 'counter', namespace='/line1',
                   parameters={'topic': 'items', 'log_every': 5}),
    ]


def conveyor_talks(rt, topic='/line1/items', timeout=5.0):
    """Exercise 06b, the launch test: True when /line1/counter hears /line1/belt_sensor.

    The graph must show the sensor publishing on /line1/items and the counter subscribing to it
    (what `ros2 topic info -v /line1/items` lists), and messages must flow there.
    """
    def names(endpoints):
        return {f"{e.node_namespace.rstrip('/')}/{e.node_name}" for e in endpoints}

    def wired():
        return ('/line1/belt_sensor' in names(rt.graph.get_publishers_info_by_topic(topic))
                and '/line1/counter' in names(rt.graph.get_subscriptions_info_by_topic(topic)))

    if not rt.poll_until(wired, timeout):  # discovery may still be under way: give it time
        return False
    heard = rt.wait_for_messages(topic, 'std_msgs/msg/String', count=3, timeout=timeout)
    return all(msg.data.startswith('item ') for msg in heard)


class ConveyorLaunchTest:
    """Exercise 06b's two halves together, as a launch test keeps them: the description and the proof."""

    describe = staticmethod(conveyor_launch)
    proves_they_talk = staticmethod(conveyor_talks)
