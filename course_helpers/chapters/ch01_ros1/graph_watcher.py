"""A ROS 2 node that tells the kernel which nodes it sees: ``rt.spawn('watcher', GraphWatcher)``.

It is what a restarted process knows of the graph: discovery fills it in with no master to ask.
Given a topic, it also listens there, like any new listener.
"""

from __future__ import annotations

from rclpy.node import Node
from std_msgs.msg import String

from course_helpers.core.channel import report
from course_helpers.core.names import node_full_names


class GraphWatcher(Node):
    """Reports ``report('graph', nodes=[...])`` (sorted full names, itself left out) whenever it changes.

    With ``topic``, it also subscribes to that String topic and reports ``report('heard', data=...)``.
    """

    def __init__(self, name: str = "watcher", period_s: float = 0.05, topic: str | None = None):
        super().__init__(name)
        self.seen: list[str] = []
        self.timer = self.create_timer(period_s, self.look)  # period in seconds
        if topic is not None:
            self.subscription = self.create_subscription(String, topic, self.on_message, 10)

    def look(self) -> None:
        me = self.get_fully_qualified_name()
        nodes = sorted(n for n in node_full_names(self.get_node_names_and_namespaces()) if n != me)
        if nodes != self.seen:
            self.seen = nodes
            report("graph", nodes=nodes)

    def on_message(self, msg: String) -> None:
        report("heard", data=msg.data)
