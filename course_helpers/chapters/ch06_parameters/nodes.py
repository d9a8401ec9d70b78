"""The configurable nodes that chapter 06 starts, in the kernel or in child processes.

:class:`RateTalker` publishes at a rate that can change while it runs; :class:`CountingListener`
logs one line every ``log_every`` messages. Both take their settings as parameters;
:func:`make_configured_node` builds one from a parameter file and values, in a child process.
"""

from __future__ import annotations

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import String

from course_helpers.chapters.ch06_parameters.files import params_file_arguments
from course_helpers.core.channel import report
from course_helpers.core.errors import CourseError


def _range_descriptor(description: str, low: float, high: float) -> ParameterDescriptor:
    return ParameterDescriptor(description=description, floating_point_range=[
        FloatingPointRange(from_value=low, to_value=high, step=0.0)])


class RateTalker(Node):
    """Publishes '<message> N' on ``topic`` at ``rate_hz``; rate and message can change while it runs."""

    def __init__(self, name: str = "talker", **node_kwargs):
        super().__init__(name, **node_kwargs)
        self.declare_parameter("topic", "chatter", ParameterDescriptor(
            description="topic to publish on (fixed at start)", read_only=True))
        self.declare_parameter("rate_hz", 2.0, _range_descriptor("publish rate [Hz]", 0.5, 50.0))
        self.declare_parameter("message", "hello", ParameterDescriptor(description="text before the count"))
        self.count = 0
        self.publisher = self.create_publisher(String, self.get_parameter("topic").value, 10)
        self.timer = self.create_timer(1.0 / self.get_parameter("rate_hz").value, self.tick)
        self.add_post_set_parameters_callback(self.on_parameters_set)

    def on_parameters_set(self, parameters: list[Parameter]) -> None:
        for parameter in parameters:
            if parameter.name == "rate_hz":
                self.timer.timer_period_ns = int(1e9 / parameter.value)  # period [ns]

    def tick(self) -> None:
        self.publisher.publish(String(data=f"{self.get_parameter('message').value} {self.count}"))
        self.count += 1


class CountingListener(Node):
    """Subscribes to ``topic`` and logs a line every ``log_every`` messages.

    In a child process it also reports ``heard`` (count, last message) over the process channel
    at the first message and with every log line, so the kernel can tell that it hears.
    """

    def __init__(self, name: str = "listener", **node_kwargs):
        super().__init__(name, **node_kwargs)
        self.declare_parameter("topic", "chatter", ParameterDescriptor(
            description="topic to listen to (fixed at start)", read_only=True))
        self.declare_parameter("log_every", 10, ParameterDescriptor(
            description="log one line per this many messages",
            integer_range=[IntegerRange(from_value=1, to_value=1000, step=1)]))
        self.heard = 0
        self.subscription = self.create_subscription(String, self.get_parameter("topic").value,
                                                     self.on_message, 10)

    def on_message(self, msg: String) -> None:
        self.heard += 1
        logs = self.heard % self.get_parameter("log_every").value == 0
        if logs:
            self.get_logger().info(f"heard {self.heard} messages, last: {msg.data}")
        if logs or self.heard == 1:
            report("heard", count=self.heard, last=msg.data)


NODE_KINDS = {"talker": RateTalker, "listener": CountingListener}


def node_class(kind: str) -> type[Node]:
    """The class of a node kind ('talker' or 'listener'); raises :class:`CourseError` for another."""
    if kind not in NODE_KINDS:
        raise CourseError(f"kind must be one of {', '.join(sorted(NODE_KINDS))}, got {kind!r}")
    return NODE_KINDS[kind]


def make_configured_node(kind: str, name: str, namespace: str = "", parameters: dict | None = None,
                         params_file: str | None = None) -> Node:
    """Child-process target: a :data:`NODE_KINDS` node with a parameter file and/or parameter values.

    Args:
        kind: 'talker' or 'listener'.
        name, namespace: the node's name and namespace.
        parameters: name -> value; like a launch file's ``Node(parameters=[file, {...}])``, they
            override the values of ``params_file``.
        params_file: a ``--params-file`` YAML file.

    Returns the node; raises :class:`CourseError` for an unknown kind or a missing file.
    """
    # rcl reads the file (--ros-args --params-file FILE); the values given here override its values
    overrides = [Parameter(key, value=value) for key, value in (parameters or {}).items()]
    cli_args = params_file_arguments(params_file) if params_file else None
    return node_class(kind)(name, namespace=namespace, parameter_overrides=overrides, cli_args=cli_args)
