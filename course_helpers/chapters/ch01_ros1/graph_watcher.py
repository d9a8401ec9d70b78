"""A ROS 2 node that tells the kernel which nodes it sees: ``rt.spawn('watcher', GraphWatcher)``.

It is what a restarted process knows of the graph: discovery fills it in with no master to ask.
"""

from __future__ import annotations

from rclpy.node import Node

from course_helpers.core.channel import report
from course_helpers.core.names import node_full_names


class GraphWatcher(Node):
    """Reports ``report('graph', nodes=[...])`` (sorted full names, itself left out) whenever it changes."""

    def __init__(self, name: str = "watcher", period_s: float = 0.05):
        super().__init__(name)
        self.seen: list[str] = []
        self.timer = self.create_timer(period_s, self.look)  # period in seconds

    def look(self) -> None:
        me = self.get_fully_qualified_name()
        nodes = sorted(n for n in node_full_names(self.get_node_names_and_namespaces()) if n != me)
        if nodes != self.seen:
            self.seen = nodes
            report("graph", nodes=nodes)
