"""The state board: every robot node's latched ``~/_state``, collected into a table.

:func:`state_graph` is the board's own part of the ROS graph: the ``~/_state`` topics are
hidden (leading underscore), so the usual graph view leaves them, and the board's
connections, out.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

from rclpy.node import Node
from std_msgs.msg import String

from course_helpers.chapters.ch10_capstone.channels import LATCHED_QOS
from course_helpers.viz.snapshot import GraphSnapshot, graph_snapshot


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
                    String, topic, partial(self.on_state, node), LATCHED_QOS)

    def on_state(self, node: str, msg: String) -> None:
        self.states[node] = msg.data

    def table(self, nodes: list[str] | None = None) -> str:
        """The current states as an aligned table, sorted by node name."""
        names = nodes if nodes is not None else list(self.states)
        return state_table({n: self.states.get(n, "(no state yet)") for n in names})


def state_table(*columns: dict[str, str], titles: tuple[str, ...] = ("state",)) -> str:
    """Aligned text table of one or more {node: state} snapshots (e.g. before and after).

    ``titles`` head the columns (one per snapshot). Returns the table, one row per node, sorted.
    """
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
    """Refresh ``board`` until it has a state for every node in ``nodes`` and ``until(states)`` holds.

    Returns: {node: state} of ``nodes``, sorted. Raises WaitTimeout after ``timeout`` s.
    """
    def ready() -> bool:
        rt.call_in_executor(board.refresh)
        have = all(n in board.states for n in nodes)
        return have and (until is None or until(dict(board.states)))

    rt.wait_until(ready, timeout, f"the states of {', '.join(nodes)}")
    return {n: board.states[n] for n in sorted(nodes)}


def state_graph(rt, board: StateBoard, timeout: float = 10.0) -> GraphSnapshot:
    """The graph of ``board`` alone: the nodes publishing the ``~/_state`` topics it reads, those
    (hidden) topics, and the board. Draw it with ``draw_graph(snapshot=state_graph(rt, board))``.

    Samples can flow before the graph ties their publisher to its node (that link arrives in a
    discovery message of its own), so this waits up to ``timeout`` s until every node the board
    has heard from is in the graph.

    Returns: a :class:`~course_helpers.viz.snapshot.GraphSnapshot` holding only those edges.
    """
    watched = set(board.subscriptions_by_topic)
    heard = {topic[: -len("/_state")] for topic in watched} & set(board.states)

    def topic_of(edge) -> str:
        return edge.target if edge.role == "publisher" else edge.source

    def snapshot() -> GraphSnapshot:
        full = graph_snapshot(rt, include_hidden=True)
        edges = [e for e in full.edges if topic_of(e) in watched]
        nodes = {e.source for e in edges if e.role == "publisher"} | {e.target for e in edges
                                                                        if e.role == "subscriber"}
        return GraphSnapshot(domain_id=full.domain_id, nodes=sorted(nodes),
                             topics={t: full.topics[t] for t in sorted({topic_of(e) for e in edges})},
                             edges=edges, include_hidden=True)

    latest = {}

    def complete() -> bool:
        latest["snapshot"] = snapshot()
        return heard <= set(latest["snapshot"].nodes)

    rt.wait_until(complete, timeout, f"the graph to show the publishers of {', '.join(sorted(heard))}")
    return latest["snapshot"]
