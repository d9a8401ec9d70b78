"""Four communication models routed message by message: peer to peer, broker, broadcast, DDS databus.

:func:`simulate_model` routes one round of messages for a number of nodes and counts the
connections, the copies each process handles and the deliveries nobody wanted;
:func:`compare_models` does it for every model and node count, :func:`plot_models` draws it,
and :func:`center_failure_table` says what survives when the busiest process fails.
"""

from __future__ import annotations

from dataclasses import dataclass

from course_helpers.core.errors import CourseError

MODELS = {
    "peer_to_peer": "peer to peer: every sender keeps a connection to every receiver it knows",
    "broker": "broker: everybody connects to one central broker that forwards each message",
    "broadcast": "broadcast: one shared channel, everybody receives everything",
    "dds_databus": "DDS databus: discovery matches each writer with the readers of its topic",
}


@dataclass
class ModelResult:
    """What one communication model costs for ``nodes`` nodes (each publishes one topic)."""

    model: str
    nodes: int
    interested: int  # receivers per topic
    connections: int  # point-to-point links (a shared channel counts as one)
    addresses_to_configure: int  # addresses someone must write into a configuration
    transmissions: int  # message copies sent per round (every node publishes once)
    busiest_load: int  # copies sent + received by the busiest process in one round
    irrelevant: int  # copies received by nodes that did not want them
    delivered: int  # wanted copies that arrived
    wanted: int  # wanted copies in total


def _interested_in(publisher: int, nodes: int, interested: int) -> list[int]:
    """The receivers of ``publisher``'s topic: the next ``interested`` nodes round the ring."""
    return [(publisher + step) % nodes for step in range(1, interested + 1)]


def simulate_model(model: str, nodes: int, interested: int = 2, failed: int | None = None) -> ModelResult:
    """Route one round of messages (every node publishes once) through ``model``; count the copies.

    Node ``i`` publishes topic ``i``, wanted by the next ``interested`` nodes. ``failed`` names a
    process that is down: a node index, or ``-1`` for the central broker. Nothing is estimated:
    each copy is routed and counted.
    """
    if model not in MODELS:
        raise CourseError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
    if isinstance(nodes, bool) or not isinstance(nodes, int) or nodes < 2:
        raise CourseError(f"nodes must be a whole number >= 2, got {nodes!r}")
    if not 1 <= interested < nodes:
        raise CourseError(f"interested must be 1..{nodes - 1} (receivers per topic), got {interested!r}")
    broker = -1
    load: dict[int, int] = {}
    sent = irrelevant = delivered = 0

    def copy(sender: int, receiver: int) -> bool:
        nonlocal sent
        if failed in (sender, receiver):
            return False
        sent += 1
        load[sender] = load.get(sender, 0) + 1
        load[receiver] = load.get(receiver, 0) + 1
        return True

    for publisher in range(nodes):
        wanted_by = set(_interested_in(publisher, nodes, interested))
        if model in ("peer_to_peer", "dds_databus"):
            delivered += sum(copy(publisher, receiver) for receiver in sorted(wanted_by))
        elif model == "broker":
            if copy(publisher, broker):
                delivered += sum(copy(broker, receiver) for receiver in sorted(wanted_by))
        else:  # broadcast: one send on the shared channel, every other node receives it
            if failed == publisher:
                continue
            sent += 1
            load[publisher] = load.get(publisher, 0) + 1
            for receiver in range(nodes):
                if receiver in (publisher, failed):
                    continue
                load[receiver] = load.get(receiver, 0) + 1
                if receiver in wanted_by:
                    delivered += 1
                else:
                    irrelevant += 1
    pairs = nodes * interested
    connections = {"peer_to_peer": pairs, "dds_databus": pairs, "broker": nodes, "broadcast": 1}[model]
    addresses = {"peer_to_peer": pairs, "broker": nodes, "broadcast": 0, "dds_databus": 0}[model]
    return ModelResult(model, nodes, interested, connections, addresses, sent,
                       max(load.values(), default=0), irrelevant, delivered, pairs)


def compare_models(node_counts=(4, 8, 16, 32, 64), interested: int = 2) -> list[ModelResult]:
    """One :class:`ModelResult` per model and node count (see :func:`simulate_model`)."""
    return [simulate_model(model, n, interested) for model in MODELS for n in node_counts]


def busiest_process(model: str) -> int:
    """The index of the process that handles the most copies in ``model`` (-1 is the broker)."""
    return -1 if model == "broker" else 0  # in the other models every node carries the same load


def center_failure_table(nodes: int = 10, interested: int = 2) -> list[dict]:
    """One row per model: which process failed (its busiest), and the wanted messages still delivered.

    Each row is a dict with ``model``, ``failed`` (text), ``delivered``, ``wanted`` and ``share`` (0..1).
    """
    rows = []
    for model in MODELS:
        down = busiest_process(model)
        result = simulate_model(model, nodes, interested, failed=down)
        rows.append({"model": model, "failed": "the broker" if down == -1 else f"node {down}",
                     "delivered": result.delivered, "wanted": result.wanted,
                     "share": result.delivered / result.wanted})
    return rows


def plot_models(results: list[ModelResult]):
    """A matplotlib figure of ``results`` against the number of nodes, in three panels: connections,
    copies at the busiest process, irrelevant copies."""
    import matplotlib.pyplot as plt

    styles = {"peer_to_peer": ("#2563eb", "o"), "broker": ("#dc2626", "s"),
              "broadcast": ("#d97706", "^"), "dds_databus": ("#16a34a", "D")}
    panels = [("connections", "point-to-point connections"),
              ("busiest_load", "copies handled by the busiest process\n(one round)"),
              ("irrelevant", "copies delivered to nodes\nthat did not want them")]
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    for ax, (attr, title) in zip(axes, panels, strict=True):
        for model, (colour, marker) in styles.items():
            rows = sorted((r for r in results if r.model == model), key=lambda r: r.nodes)
            dashed = model == "dds_databus"  # it coincides with peer to peer in the first panel
            ax.plot([r.nodes for r in rows], [getattr(r, attr) for r in rows], marker=marker,
                    color=colour, label=model.replace("_", " "), linewidth=1.5, markersize=4,
                    linestyle="--" if dashed else "-")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("nodes")
        ax.set_xscale("log", base=2)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    interested = results[0].interested if results else 0
    fig.suptitle(f"Four communication models, each node publishing one topic wanted by {interested} "
                 "others", fontsize=11)
    fig.tight_layout()
    return fig
