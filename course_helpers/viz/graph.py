"""The live ROS computation graph, drawn like rqt_graph (chapters 01 and 03-10).

Chapter 01 introduces the computation graph, drawn from the live system; the
later chapters draw it after starting their nodes so students see what they
built: 03 topics (many-to-many), 04 services (``show_services=True``), 05 the
topics and services an action is built on (``include_hidden=True``), 06 a set of
child-process nodes started together, 07 nodes of other processes in the same
domain, 08 the QoS lab's publishers and subscribers, 09 a colcon-built package's
node joining the notebook's graph, 10 the capstone's robots by namespace.

Everything comes from the live graph of the kernel's ROS domain, asked through the
runtime's hidden node, so nodes in child processes (or in another program on the
same domain) appear as well:

* :func:`graph_snapshot` returns the graph as plain data (nodes, topics, edges
  labelled with their types, services and actions);
* :func:`draw_graph` draws it with matplotlib: nodes as rounded boxes, topics as
  rectangles, arrows publisher -> topic -> subscriber, laid out in deterministic
  layers from left to right;
* :func:`live_graph` shows a widget that redraws the picture every second while
  the notebook keeps running.

Like ``ros2 node list`` and rqt_graph, the view hides infrastructure unless asked
(``include_hidden=True``): nodes whose name starts with ``_``, names with a part
starting with ``_`` (the ``/_action/`` topics and services behind every action),
``/rosout``, ``/parameter_events`` and each node's parameter and type-description
services.
"""

from __future__ import annotations

import functools
import io
import math
import threading
from dataclasses import dataclass, field
from itertools import pairwise

import networkx as nx
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch, Patch
from matplotlib.textpath import TextToPath
from rclpy.action.graph import (
    get_action_client_names_and_types_by_node,
    get_action_server_names_and_types_by_node,
)

from course_helpers.core.errors import CourseError

HIDDEN_TOPICS = frozenset({"/rosout", "/parameter_events"})
# Services every node offers for its parameters and interface descriptions.
INFRASTRUCTURE_SERVICES = frozenset({
    "describe_parameters", "get_parameter_types", "get_parameters", "list_parameters",
    "set_parameters", "set_parameters_atomically", "get_type_description",
})


# ---------------------------------------------------------------------- data
@dataclass(frozen=True, order=True)
class Edge:
    """One arrow of the graph: ``source -> target`` carrying ``type``.

    Topic edges go publisher node -> topic and topic -> subscriber node; service
    edges client node -> service -> server node; action edges client -> action ->
    server. ``type`` is the full interface name, e.g. ``std_msgs/msg/String``.
    """

    source: str
    target: str
    type: str
    kind: str = "topic"
    role: str = "publisher"  # the node's role: publisher, subscriber, client or server

    @property
    def short_type(self) -> str:
        """The type as rqt and most docs abbreviate it: ``std_msgs/String``."""
        return short_type(self.type)


@dataclass
class GraphSnapshot:
    """The ROS graph at one moment, as plain sorted data (compare it, print it, draw it)."""

    domain_id: int | None
    nodes: list[str] = field(default_factory=list)
    topics: dict[str, list[str]] = field(default_factory=dict)
    edges: list[Edge] = field(default_factory=list)
    services: dict[str, list[str]] = field(default_factory=dict)
    service_edges: list[Edge] = field(default_factory=list)
    actions: dict[str, list[str]] = field(default_factory=dict)
    action_edges: list[Edge] = field(default_factory=list)
    include_hidden: bool = False

    def publishers(self, topic: str) -> list[str]:
        """Nodes publishing on ``topic``, sorted."""
        return sorted({e.source for e in self.edges if e.target == topic})

    def subscribers(self, topic: str) -> list[str]:
        """Nodes subscribed to ``topic``, sorted."""
        return sorted({e.target for e in self.edges if e.source == topic})

    def as_text(self) -> str:
        """One line per node and per topic edge, sorted (stable enough for nbval)."""
        lines = [f"nodes: {', '.join(self.nodes) or '(none)'}"]
        lines += [f"{e.source} -> {e.target} [{e.short_type}]" for e in self.edges]
        lines += [f"{e.source} -> {e.target} [{e.short_type}] (service)" for e in self.service_edges]
        lines += [f"{e.source} -> {e.target} [{e.short_type}] (action)" for e in self.action_edges]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.as_text()


def short_type(full: str) -> str:
    """``std_msgs/msg/String`` -> ``std_msgs/String`` (other shapes are returned unchanged)."""
    parts = full.split("/")
    if len(parts) == 3 and parts[1] in ("msg", "srv", "action"):
        return f"{parts[0]}/{parts[2]}"
    return full


def is_hidden_node(fqn: str) -> bool:
    """True for nodes ros2cli hides: their base name starts with ``_``."""
    return fqn.rsplit("/", 1)[-1].startswith("_")


def is_hidden_topic(name: str) -> bool:
    """True for ``/rosout``, ``/parameter_events`` and names with a part starting with ``_``."""
    return name in HIDDEN_TOPICS or any(part.startswith("_") for part in name.split("/"))


def is_hidden_service(name: str) -> bool:
    """True for parameter/type-description services and names with a part starting with ``_``."""
    parts = name.split("/")
    return parts[-1] in INFRASTRUCTURE_SERVICES or any(p.startswith("_") for p in parts)


def _fqn(name: str, namespace: str) -> str:
    return namespace.rstrip("/") + "/" + name


def _resolve_runtime(rt):
    if rt is None:
        from course_helpers.core.runtime import get_runtime

        return get_runtime()
    if not hasattr(rt, "graph"):
        raise CourseError(f"rt must be the course runtime (rt = get_runtime()), got {type(rt).__name__}")
    return rt


def graph_snapshot(rt=None, include_hidden: bool = False) -> GraphSnapshot:
    """Ask the live graph which nodes exist and what each publishes, subscribes, serves and calls.

    Nodes of every process in the runtime's domain are included. Infrastructure
    (see the module docstring) is left out unless ``include_hidden=True``.
    """
    rt = _resolve_runtime(rt)
    return snapshot_of(rt.graph, rt.domain.domain_id, include_hidden)


def snapshot_of(graph, domain_id: int | None = None, include_hidden: bool = False) -> GraphSnapshot:
    """:func:`graph_snapshot` asked through any rclpy node (``graph``) instead of the runtime."""
    snap = GraphSnapshot(domain_id=domain_id, include_hidden=include_hidden)
    topic_types: dict[str, set[str]] = {}
    service_types: dict[str, set[str]] = {}
    action_types: dict[str, set[str]] = {}
    edges: set[Edge] = set()
    service_edges: set[Edge] = set()
    action_edges: set[Edge] = set()

    def collect(query, name, namespace, role, kind, hidden, types, into):
        try:
            found = query(name, namespace)
        except Exception:  # the node left the graph between listing and asking
            return False
        fqn = _fqn(name, namespace)
        for endpoint, endpoint_types in found:
            if hidden(endpoint) and not include_hidden:
                continue
            types.setdefault(endpoint, set()).update(endpoint_types)
            for type_name in endpoint_types:
                into.add(Edge(fqn, endpoint, type_name, kind, role) if role in ("publisher", "client")
                         else Edge(endpoint, fqn, type_name, kind, role))
        return True

    nodes = set()
    for name, namespace in sorted(set(graph.get_node_names_and_namespaces()), key=lambda p: p[::-1]):
        fqn = _fqn(name, namespace)
        if is_hidden_node(fqn) and not include_hidden:
            continue
        if not collect(graph.get_publisher_names_and_types_by_node, name, namespace, "publisher", "topic",
                       is_hidden_topic, topic_types, edges):
            continue
        nodes.add(fqn)
        collect(graph.get_subscriber_names_and_types_by_node, name, namespace, "subscriber", "topic",
                is_hidden_topic, topic_types, edges)
        collect(graph.get_client_names_and_types_by_node, name, namespace, "client", "service",
                is_hidden_service, service_types, service_edges)
        collect(graph.get_service_names_and_types_by_node, name, namespace, "server", "service",
                is_hidden_service, service_types, service_edges)
        collect(lambda n, ns: get_action_client_names_and_types_by_node(graph, n, ns), name, namespace,
                "client", "action", lambda _a: False, action_types, action_edges)
        collect(lambda n, ns: get_action_server_names_and_types_by_node(graph, n, ns), name, namespace,
                "server", "action", lambda _a: False, action_types, action_edges)

    snap.nodes = sorted(nodes)
    snap.topics = {t: sorted(types) for t, types in sorted(topic_types.items())}
    snap.edges = sorted(edges)
    snap.services = {s: sorted(types) for s, types in sorted(service_types.items())}
    snap.service_edges = sorted(service_edges)
    snap.actions = {a: sorted(types) for a, types in sorted(action_types.items())}
    snap.action_edges = sorted(action_edges)
    return snap


# ---------------------------------------------------------------------- layout
_FONT_PT = 9.0        # names in boxes
_LABEL_PT = 7.0       # edge labels (types)
_PAD_IN = 0.10        # space between a name and its box
_ROW_IN = 0.62        # vertical slot of a box in its column
_DUMMY_IN = 0.30      # vertical slot of an edge passing through a column
_MARGIN_IN = 0.35
_TITLE_IN = 0.45
_LEGEND_IN = 0.35
_PART_GAP_IN = 0.15   # extra space between unconnected parts of the graph
_PORT_IN = 0.055      # distance between arrows leaving or entering one side of a box
_PORT_TB_IN = 0.12    # the same on the top and bottom sides (top-down layout)
_LAYER_GAP_TB_IN = 0.7   # between layers of a top-down layout (room for a label)
_SIBLING_GAP_TB_IN = 0.3  # between boxes side by side in a top-down layout
_NOTEBOOK_IN = 13.0   # wider than this, a notebook shrinks the picture: try top-down instead

_STYLE = {  # kind: (box style, face colour, edge colour, line style)
    "node": ("round,pad={pad},rounding_size=0.12", "#dbeafe", "#1d4ed8", "-"),
    "topic": ("square,pad={pad}", "#fef9c3", "#a16207", "-"),
    "service": ("square,pad={pad}", "#ede9fe", "#6d28d9", "--"),
    "action": ("round4,pad={pad}", "#fce7f3", "#be185d", "-"),
}
_EDGE_COLOUR = {"topic": "#374151", "service": "#6d28d9", "action": "#be185d"}
_DUMMY = "~edge"      # kind of the invisible points long edges pass through

_text_to_path = TextToPath()


def _text_width_in(text: str, size_pt: float, bold: bool = False) -> float:
    font = FontProperties(size=size_pt, weight="bold" if bold else "normal")
    width, _height, _descent = _text_to_path.get_text_width_height_descent(text, font, ismath=False)
    return width / 72.0


def _build_digraph(snap: GraphSnapshot, show_services: bool, show_actions: bool) -> nx.DiGraph:
    """Vertices are (kind, name) pairs, so a node and a topic may share a name."""
    g = nx.DiGraph()
    g.add_nodes_from(("node", fqn) for fqn in snap.nodes)
    g.add_nodes_from(("topic", topic) for topic in snap.topics)
    groups = [("topic", snap.edges)]
    if show_services:
        groups.append(("service", snap.service_edges))
        g.add_nodes_from(("service", service) for service in snap.services)
    if show_actions:
        groups.append(("action", snap.action_edges))
        g.add_nodes_from(("action", action) for action in snap.actions)
    for kind, edges in groups:
        for e in edges:
            node_first = e.role in ("publisher", "client")
            src = ("node", e.source) if node_first else (kind, e.source)
            dst = (kind, e.target) if node_first else ("node", e.target)
            labels = g.edges[src, dst]["types"] if g.has_edge(src, dst) else []
            g.add_edge(src, dst, types=sorted({*labels, e.short_type}), kind=kind)
    return g


def _layers(g: nx.DiGraph) -> dict:
    """Column of every vertex: longest-path layering once cycles' back edges are turned round.

    Depth-first search from the vertices that only send (nodes first), in sorted
    order, so the result never depends on discovery order.
    """
    dag = nx.DiGraph()
    dag.add_nodes_from(g.nodes)
    state: dict = {}
    roots = sorted(g.nodes, key=lambda v: (g.in_degree(v) > 0, g.in_degree(v) - g.out_degree(v),
                                           v[0] != "node", v))
    for root in roots:
        if root in state:
            continue
        state[root] = "open"
        stack = [(root, iter(sorted(g.successors(root))))]
        while stack:
            vertex, successors = stack[-1]
            nxt = next(successors, None)
            if nxt is None:
                state[vertex] = "done"
                stack.pop()
            elif state.get(nxt) == "open":
                dag.add_edge(nxt, vertex)  # a back edge: lay it out the other way round
            else:
                dag.add_edge(vertex, nxt)
                if nxt not in state:
                    state[nxt] = "open"
                    stack.append((nxt, iter(sorted(g.successors(nxt)))))
    layer = {}
    for v in nx.lexicographical_topological_sort(dag):
        layer[v] = max((layer[u] + 1 for u in dag.predecessors(v)), default=0)
    # Pull vertices that only send (a publisher, a topic nobody publishes yet) next to what they feed.
    for v in sorted(dag.nodes, key=lambda v: -layer[v]):
        if dag.in_degree(v) == 0 and dag.out_degree(v) > 0:
            layer[v] = min(layer[s] for s in dag.successors(v)) - 1
    return layer


@dataclass
class _Route:
    """How one edge is drawn: the vertices it passes, left to right, and its direction."""

    src: tuple
    dst: tuple
    chain: list        # [left end, dummies..., right end]
    forward: bool      # False: drawn right to left (a back edge of a cycle)
    kind: str
    label: str


@dataclass
class _Layout:
    vertices: list     # real vertices (kind, name), sorted
    pos: dict          # vertex or dummy -> (x, y) in inches
    half: dict         # vertex -> (half width, half height) of its box; dummies: half the layer's depth
    routes: list
    ports: dict        # (route index, vertex, "out" | "in") -> offset where the edge meets that box
    width: float
    height: float
    orientation: str   # "LR": layers left to right; "TB": top to bottom
    scale: float = 1.0  # font and line scale, below 1 when drawn into smaller axes


def _layout(g: nx.DiGraph, orientation: str = "auto") -> _Layout:
    """Place every box: layers along the flow, then an order across it that avoids crossings."""
    if orientation == "auto":  # left to right, unless too wide for a notebook and top-down is narrower
        wide = _layout(g, "LR")
        if wide.width <= _NOTEBOOK_IN:
            return wide
        tall = _layout(g, "TB")
        return tall if tall.width < wide.width else wide
    lr = orientation == "LR"
    layer = _layers(g)
    routes = []
    for src, dst, data in sorted(g.edges(data=True)):
        forward = layer[dst] > layer[src]
        first, last = (src, dst) if forward else (dst, src)
        dummies = [(_DUMMY, f"{src}>{dst}#{col:04d}") for col in range(layer[first] + 1, layer[last])]
        for col, dummy in zip(range(layer[first] + 1, layer[last]), dummies, strict=True):
            layer[dummy] = col
        routes.append(_Route(src, dst, [first, *dummies, last], forward, data["kind"],
                             " / ".join(data["types"])))
    neighbours: dict = {v: [] for v in layer}
    for route in routes:
        for a, b in pairwise(route.chain):
            neighbours[a].append(b)
            neighbours[b].append(a)
    half = {}
    for v in g.nodes:
        half[v] = (_text_width_in(v[1], _FONT_PT, bold=v[0] == "node") / 2 + _PAD_IN,
                   _FONT_PT / 72 / 2 + _PAD_IN)
    if lr:  # room for a type label between two layers
        gap = max(0.9, max((_text_width_in(r.label, _LABEL_PT) for r in routes), default=0.4) + 0.45)
    else:
        gap = _LAYER_GAP_TB_IN

    label_half = {}  # top-down: the labels of a vertex's outgoing edges sit beside it
    for route in routes:
        source = route.src if route.forward else route.chain[-1]
        label_half[source] = max(label_half.get(source, 0.0), _text_width_in(route.label, _LABEL_PT) / 2)

    def slot(v):  # room a vertex takes across the flow
        if v[0] == _DUMMY:
            return _DUMMY_IN
        return _ROW_IN if lr else 2 * max(half[v][0], label_half.get(v, 0.0)) + _SIBLING_GAP_TB_IN

    # Lay out each connected part on its own and stack the parts across the flow, largest first.
    across = {}
    edge = 0.0
    for part in _connected_parts(neighbours):
        part_columns = _order_columns({v: layer[v] for v in part}, neighbours)
        part_across = _vertical_positions(part_columns, neighbours, slot)
        part_top = max(part_across[v] + slot(v) / 2 for v in part)
        for v in part:
            across[v] = part_across[v] - part_top + edge
        edge = min(across[v] - slot(v) / 2 for v in part) - _PART_GAP_IN

    columns: list[list] = [[] for _ in range(max(layer.values(), default=-1) + 1)]
    for v in sorted(layer):
        columns[layer[v]].append(v)
    pos = {}
    depth = 0.0
    for column in columns:
        thick = max((half[v][0 if lr else 1] for v in column if v[0] != _DUMMY), default=0.05)
        for v in column:
            pos[v] = (depth + thick, across[v]) if lr else (-across[v], -(depth + thick))
            if v[0] == _DUMMY:
                half[v] = (thick, 0.0) if lr else (0.0, thick)
        depth += 2 * thick + gap

    # Fit the drawing between the margins, the title above and the legend below.
    xs = [c for v in pos for c in (pos[v][0] - half[v][0], pos[v][0] + half[v][0])] or [0.0, 1.0]
    ys = [c for v in pos for c in (pos[v][1] - half[v][1], pos[v][1] + half[v][1])] or [0.0, 1.0]
    dx, dy = _MARGIN_IN - min(xs), _LEGEND_IN + _MARGIN_IN / 2 - min(ys)
    pos = {v: (x + dx, y + dy) for v, (x, y) in pos.items()}
    width = max(max(xs) - min(xs) + 2 * _MARGIN_IN, 4.0)
    height = max(ys) - min(ys) + _TITLE_IN + _LEGEND_IN + _MARGIN_IN
    if width > max(xs) - min(xs) + 2 * _MARGIN_IN:  # centre a narrow drawing
        pos = {v: (x + (width - (max(xs) - min(xs)) - 2 * _MARGIN_IN) / 2, y) for v, (x, y) in pos.items()}
    # Whole quarter inches keep the figure's text repr short and stable.
    width, height = math.ceil(width * 4) / 4, math.ceil(height * 4) / 4
    return _Layout(sorted(g.nodes), pos, half, routes, _ports(routes, pos, half, lr), width, height,
                   orientation)


def _connected_parts(neighbours: dict) -> list[list]:
    """Connected groups of vertices, largest first, then by name (so the stacking is stable)."""
    seen: set = set()
    parts = []
    for start in sorted(neighbours):
        if start in seen:
            continue
        seen.add(start)
        part, todo = [], [start]
        while todo:
            v = todo.pop()
            part.append(v)
            for u in neighbours[v]:
                if u not in seen:
                    seen.add(u)
                    todo.append(u)
        parts.append(sorted(part))
    return sorted(parts, key=lambda part: (-len(part), part[0]))


def _order_columns(layer: dict, neighbours: dict) -> list[list]:
    """Vertices of each column, ordered to reduce crossings.

    Two starting orders (depth-first, which keeps chains together, and by name)
    are improved by barycentre sweeps and by swapping neighbours while that
    removes crossings; the order with the fewest crossings wins. Ties go by name,
    so the same graph always gets the same picture.
    """
    by_name: list[list] = [[] for _ in range(max(layer.values(), default=-1) + 1)]
    for v in sorted(layer):
        by_name[layer[v]].append(v)
    by_visit: list[list] = [[] for _ in by_name]
    seen: set = set()
    for start in (v for column in by_name for v in column):
        todo = [start]
        while todo:
            v = todo.pop()
            if v in seen:
                continue
            seen.add(v)
            by_visit[layer[v]].append(v)
            todo.extend(sorted(neighbours[v], reverse=True))
    best, best_crossings = by_visit, None
    for start in (by_visit, by_name):
        columns, count = _improve_order([list(c) for c in start], neighbours)
        if best_crossings is None or count < best_crossings:
            best, best_crossings = columns, count
    return best


def _index_of(column: list) -> dict:
    return {v: i for i, v in enumerate(column)}


def _crossings(columns: list[list], neighbours: dict) -> int:
    """How many pairs of edges cross between neighbouring columns."""
    total = 0
    for left, right in pairwise(columns):
        where = _index_of(right)
        ends = sorted((i, where[u]) for i, v in enumerate(left) for u in neighbours[v] if u in where)
        total += sum(1 for k, (a1, b1) in enumerate(ends) for a2, b2 in ends[k + 1:] if a1 < a2 and b1 > b2)
    return total


def _pair_crossings(u, v, ci: int, columns: list[list], neighbours: dict) -> int:
    """Crossings between the edges of u and of v (u placed before v) to the neighbouring columns."""
    count = 0
    for other in (ci - 1, ci + 1):
        if 0 <= other < len(columns):
            where = _index_of(columns[other])
            pu = [where[w] for w in neighbours[u] if w in where]
            pv = [where[w] for w in neighbours[v] if w in where]
            count += sum(1 for a in pu for b in pv if a > b)
    return count


def _centred(column: list) -> dict:
    return {v: i - (len(column) - 1) / 2 for i, v in enumerate(column)}


def _improve_order(columns: list[list], neighbours: dict) -> tuple[list[list], int]:
    """Barycentre sweeps and swaps from one starting order; the best order seen and its crossings."""
    best, best_crossings = [list(c) for c in columns], _crossings(columns, neighbours)
    for _sweep in range(4):
        for direction in (range(1, len(columns)), range(len(columns) - 2, -1, -1)):
            for ci in direction:
                ref = {}
                for other in (ci - 1, ci + 1):
                    if 0 <= other < len(columns):
                        ref.update(_centred(columns[other]))
                current = _centred(columns[ci])

                def key(v, ref=ref, current=current):
                    near = [ref[u] for u in neighbours[v] if u in ref]
                    return (sum(near) / len(near) if near else current[v], v)

                columns[ci] = sorted(columns[ci], key=key)
        improved = True
        while improved:
            improved = False
            for ci, column in enumerate(columns):
                for i in range(len(column) - 1):
                    u, v = column[i], column[i + 1]
                    if (_pair_crossings(v, u, ci, columns, neighbours)
                            < _pair_crossings(u, v, ci, columns, neighbours)):
                        column[i], column[i + 1] = v, u
                        improved = True
        count = _crossings(columns, neighbours)
        if count < best_crossings:
            best, best_crossings = [list(c) for c in columns], count
    return best, best_crossings


def _vertical_positions(columns: list[list], neighbours: dict, slot) -> dict:
    """Positions across the flow (inches, around 0) that line vertices up with their neighbours.

    Minimises the summed squared offsets between neighbours while keeping each
    column's order and spacing: each sweep puts a column at its best place given
    the others (the neighbours' mean height, fitted to the order by weighted
    isotonic regression), so one-to-one chains end up straight and nothing overlaps.
    """
    ys = {}
    for column in columns:
        top = sum(slot(v) for v in column) / 2
        for v in column:
            ys[v] = top - slot(v) / 2
            top -= slot(v)
    for _sweep in range(500):  # until nothing moves more than a thousandth of a point
        moved = 0.0
        for column in columns:
            wanted, weights = [], []
            for v in column:
                near = [ys[u] for u in neighbours[v]]
                wanted.append(sum(near) / len(near) if near else ys[v])
                weights.append(max(len(near), 1))
            fitted = _fit_in_order(wanted, weights, [slot(v) for v in column])
            for v, y in zip(column, fitted, strict=True):
                moved = max(moved, abs(ys[v] - y))
                ys[v] = y
        if moved < 1e-5:
            break
    return {v: round(y, 3) for v, y in ys.items()}


def _fit_in_order(wanted: list[float], weights: list[float], slots: list[float]) -> list[float]:
    """Closest heights to ``wanted`` (top to bottom) keeping neighbours ``(slot_a + slot_b) / 2`` apart.

    Weighted least squares under an order constraint: pool adjacent violators.
    """
    offsets = [0.0]
    for a, b in pairwise(slots):
        offsets.append(offsets[-1] + (a + b) / 2)
    blocks: list[list[float]] = []  # [weighted mean, weight, members]
    for w, o, weight in zip(wanted, offsets, weights, strict=True):
        blocks.append([w + o, weight, 1])  # shifted so the targets must not increase downwards
        while len(blocks) > 1 and blocks[-2][0] < blocks[-1][0]:
            mean, weight_b, members_b = blocks.pop()
            prev_mean, weight_a, members_a = blocks[-1]
            blocks[-1] = [(prev_mean * weight_a + mean * weight_b) / (weight_a + weight_b),
                          weight_a + weight_b, members_a + members_b]
    fitted = [mean for mean, _weight, members in blocks for _ in range(members)]
    return [f - o for f, o in zip(fitted, offsets, strict=True)]


def _ports(routes: list, pos: dict, half: dict, lr: bool) -> dict:
    """Spread the arrows meeting one side of a box so that they (and their labels) do not overlap."""
    sides: dict = {}
    for index, route in enumerate(routes):
        chain = route.chain
        for vertex, side, toward in ((chain[0], "out", chain[1]), (chain[-1], "in", chain[-2])):
            across = pos[toward][1] if lr else -pos[toward][0]
            sides.setdefault((vertex, side), []).append((across, index))
    ports = {}
    for (vertex, side), entries in sides.items():
        entries.sort(key=lambda e: (-e[0], e[1]))
        step_in, room = (_PORT_IN, half[vertex][1]) if lr else (_PORT_TB_IN, half[vertex][0])
        spread = min(step_in * (len(entries) - 1) / 2, 0.7 * room)
        step = 2 * spread / (len(entries) - 1) if len(entries) > 1 else 0.0
        for i, (_across, index) in enumerate(entries):
            offset = spread - i * step
            ports[index, vertex, side] = offset if lr else -offset
    return ports


# ---------------------------------------------------------------------- drawing
def _render(snap: GraphSnapshot, lay: _Layout, ax, title: bool) -> None:
    ax.set_xlim(0, lay.width)
    ax.set_ylim(0, lay.height)
    ax.set_aspect("equal", adjustable="box")
    ax.axis("off")
    if title:
        ax.text(lay.width / 2, lay.height - _TITLE_IN / 2, f"ROS graph (domain {snap.domain_id})",
                ha="center", va="center", fontsize=11 * lay.scale, fontweight="bold", gid="title")
    if not lay.vertices:
        ax.text(lay.width / 2, lay.height / 2, "no nodes in this domain yet", ha="center",
                va="center", fontsize=_FONT_PT * lay.scale, color="#6b7280", style="italic")
        return
    for kind, name in lay.vertices:
        style, face, edge, line = _STYLE[kind]
        (x, y), (hw, hh) = lay.pos[kind, name], lay.half[kind, name]
        ax.add_patch(FancyBboxPatch((x - hw + _PAD_IN, y - hh + _PAD_IN), 2 * (hw - _PAD_IN),
                                    2 * (hh - _PAD_IN), boxstyle=style.format(pad=_PAD_IN),
                                    facecolor=face, edgecolor=edge, linestyle=line, linewidth=1.3 * lay.scale,
                                    zorder=3, gid=f"{kind}:{name}"))
        ax.text(x, y, name, ha="center", va="center", fontsize=_FONT_PT * lay.scale, zorder=4,
                fontweight="bold" if kind == "node" else "normal", gid=f"label:{kind}:{name}")
    taken = [(lay.pos[v][0], lay.pos[v][1], *lay.half[v]) for v in lay.vertices]  # centre, half sizes
    for index, route in enumerate(lay.routes):
        _draw_route(ax, lay, index, route, taken)
    kinds = sorted({kind for kind, _name in lay.vertices}, key=list(_STYLE).index)
    handles = [Patch(facecolor=_STYLE[k][1], edgecolor=_STYLE[k][2], linestyle=_STYLE[k][3], label=k)
               for k in kinds]
    ax.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=_LABEL_PT * lay.scale,
              frameon=False, bbox_to_anchor=(0.5, 0.0), handlelength=1.6)


def _draw_route(ax, lay: _Layout, index: int, route: _Route, taken: list) -> None:
    """A polyline from the source's outgoing side, through the layers between, to the target."""
    first, last = route.chain[0], route.chain[-1]
    (x0, y0), (w0, h0), p0 = lay.pos[first], lay.half[first], lay.ports[index, first, "out"]
    (x1, y1), (w1, h1), p1 = lay.pos[last], lay.half[last], lay.ports[index, last, "in"]
    lr = lay.orientation == "LR"
    points = [(x0 + w0, y0 + p0) if lr else (x0 + p0, y0 - h0)]
    for dummy in route.chain[1:-1]:
        (x, y), (hw, hh) = lay.pos[dummy], lay.half[dummy]
        points += [(x - hw, y), (x + hw, y)] if lr else [(x, y + hh), (x, y - hh)]
    points.append((x1 - w1, y1 + p1) if lr else (x1 + p1, y1 + h1))
    if not route.forward:
        points.reverse()
    colour = _EDGE_COLOUR[route.kind]
    style = "--" if route.kind == "service" else "-"
    if len(points) > 2:
        xs, ys = zip(*points[:-1], strict=True)
        ax.plot(xs, ys, color=colour, linestyle=style, linewidth=1.1 * lay.scale, zorder=2)
    bend = 0.0 if route.forward or len(points) > 2 else -0.25  # a direct back edge bows out of the way
    ax.add_patch(FancyArrowPatch(points[-2], points[-1], arrowstyle="-|>",
                                 mutation_scale=11 * lay.scale, color=colour, linestyle=style,
                                 linewidth=1.1 * lay.scale, shrinkA=0, shrinkB=1,
                                 connectionstyle=f"arc3,rad={bend}", zorder=2))
    # Label the segment leaving the source, where no other label or box is in the way.
    (xa, ya), (xb, yb) = points[0], points[1]
    control = ((xa + xb) / 2 + bend * (yb - ya), (ya + yb) / 2 - bend * (xb - xa))  # arc3's Bezier
    half_w, half_h = _text_width_in(route.label, _LABEL_PT) / 2 + 0.05, _LABEL_PT / 72 / 2 + 0.04

    def spot(t):
        return ((1 - t) ** 2 * xa + 2 * t * (1 - t) * control[0] + t * t * xb,
                (1 - t) ** 2 * ya + 2 * t * (1 - t) * control[1] + t * t * yb)

    def overlap(xy):  # area shared with boxes and labels already drawn
        x, y = xy
        return sum(max(0.0, half_w + ow - abs(x - ox)) * max(0.0, half_h + oh - abs(y - oy))
                   for ox, oy, ow, oh in taken)

    candidates = [spot(t) for t in (0.5, 0.35, 0.65, 0.25, 0.75, 0.42, 0.58, 0.18, 0.82)]
    x, y = min(candidates, key=overlap)  # the first of the least crowded places
    taken.append((x, y, half_w, half_h))
    ax.text(x, y, route.label, ha="center", va="center", fontsize=_LABEL_PT * lay.scale, color=colour,
            zorder=5, gid="edge-label",
            bbox=dict(boxstyle="round,pad=0.15", facecolor="white", edgecolor="none", alpha=0.85))


def _checked_orientation(orientation: str) -> str:
    if orientation not in ("auto", "LR", "TB"):
        raise CourseError(f"orientation must be 'auto', 'LR' (left to right) or 'TB' (top to bottom), "
                          f"got {orientation!r}")
    return orientation


def draw_graph(rt=None, include_hidden: bool = False, ax=None, show_services: bool = False,
               show_actions: bool = True, snapshot: GraphSnapshot | None = None,
               orientation: str = "auto"):
    """Draw the live ROS graph of the runtime's domain and return the matplotlib Figure.

    Nodes are rounded boxes, topics rectangles; arrows go publisher -> topic ->
    subscriber and carry the message type. ``show_services=True`` adds services
    (dashed, client -> service -> server); actions are drawn unless
    ``show_actions=False``. ``include_hidden=True`` also shows the infrastructure
    ros2cli hides. The layers run left to right (``orientation='LR'``); 'auto'
    turns a graph too wide for a notebook top to bottom ('TB'). Pass ``ax`` to draw
    into your own axes, or ``snapshot`` to draw a :class:`GraphSnapshot` taken
    earlier. End the cell with ``;`` or ``plt.show()``.
    """
    _checked_orientation(orientation)
    if snapshot is None:
        snapshot = graph_snapshot(rt, include_hidden=include_hidden)
    lay = _layout(_build_digraph(snapshot, show_services, show_actions), orientation)
    if ax is None:
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=(lay.width, lay.height))
        _render(snapshot, lay, fig.add_axes((0, 0, 1, 1)), title=True)
        return fig
    fig = ax.figure
    box = ax.get_position()
    lay.scale = min(1.0, box.width * fig.get_figwidth() / lay.width,
                    box.height * fig.get_figheight() / lay.height)
    _render(snapshot, lay, ax, title=False)
    ax.set_title(f"ROS graph (domain {snapshot.domain_id})")
    return fig


def render_png(snapshot: GraphSnapshot, show_services: bool = False, show_actions: bool = True,
               dpi: int = 96, orientation: str = "auto") -> bytes:
    """Draw a snapshot into PNG bytes without pyplot (safe in background threads)."""
    lay = _layout(_build_digraph(snapshot, show_services, show_actions), _checked_orientation(orientation))
    fig = Figure(figsize=(lay.width, lay.height))
    FigureCanvasAgg(fig)
    _render(snapshot, lay, fig.add_axes((0, 0, 1, 1)), title=True)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()


# ---------------------------------------------------------------------- live widget
REFRESHER_THREAD_NAME = "ros-graph-refresher"
_live_lock = threading.Lock()
_live_views: list = []  # the refreshing view of this kernel (at most one keeps running)


def _graph_key(snap: GraphSnapshot, show_services: bool):
    return (snap.domain_id, tuple(snap.nodes), tuple(snap.topics.items()), tuple(snap.edges),
            tuple(snap.action_edges), tuple(snap.actions),
            tuple(snap.service_edges) if show_services else (), show_services)


class _LiveGraphController:
    """The refresher thread behind :func:`live_graph` (redraws only when the graph changed)."""

    def __init__(self, rt, view, period_s: float):
        self.rt = rt
        self.view = view
        self.period_s = period_s
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._last_key = None
        self.snapshot: GraphSnapshot | None = None  # the graph last drawn
        self.redraws = 0
        self.thread = threading.Thread(target=self._loop, name=REFRESHER_THREAD_NAME, daemon=True)

    def start(self):
        self.thread.start()

    def stop(self, reason: str = "stopped") -> None:
        self._stop.set()
        self._wake.set()
        if self.thread.is_alive() and threading.current_thread() is not self.thread:
            self.thread.join(timeout=5)
        self.view.status.value = f"<small><i>{reason}</i></small>"

    @property
    def running(self) -> bool:
        return self.thread.is_alive() and not self._stop.is_set()

    def kick(self) -> None:
        """Redraw at once (the checkbox and the button call this)."""
        self._last_key = None
        self._wake.set()

    def _loop(self) -> None:
        while not self._stop.is_set():
            if self.view.auto.value or self._last_key is None:
                self.refresh()
            self._wake.wait(self.period_s)
            self._wake.clear()

    def refresh(self) -> None:
        # Never go through rt.graph here: it would start a runtime that the notebook stopped.
        graph, domain = getattr(self.rt, "_internal", None), getattr(self.rt, "domain", None)
        if not self.rt.running or graph is None or domain is None:
            self.view.status.value = "<small><i>runtime stopped: run rt = get_runtime()</i></small>"
            return
        try:
            snap = snapshot_of(graph, domain.domain_id, include_hidden=self.view.hidden.value)
            show_services = self.view.services.value
            key = (_graph_key(snap, show_services), snap.include_hidden)
            if key != self._last_key:
                self.view.image.value = render_png(snap, show_services=show_services)
                self._last_key = key
                self.snapshot = snap
                self.redraws += 1
            self.view.status.value = (f"<small>{_count(len(snap.nodes), 'node')}, "
                                      f"{_count(len(snap.topics), 'topic')}</small>")
        except Exception as exc:  # keep refreshing; show what went wrong
            self.view.status.value = f"<small>graph refresh failed: {type(exc).__name__}: {exc}</small>"


def _count(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


@functools.cache
def _view_class():
    """The widget class of :func:`live_graph` (built on first use, so importing ipywidgets is lazy)."""
    import ipywidgets as w

    class LiveGraphView(w.VBox):
        """The live graph widget; ``stop()`` ends its refresher, ``close()`` also removes it."""

        def stop(self, reason: str = "stopped") -> None:
            self.controller.stop(reason)
            with _live_lock:
                if self in _live_views:
                    _live_views.remove(self)

        def close(self):
            self.stop("closed")
            for child in (self.image, self.hidden, self.services, self.auto, self.refresh_button,
                          self.status, self.controls):
                child.close()
            super().close()

        def __repr__(self):  # stable text: notebooks compare text outputs
            return f"LiveGraphView(period_s={self.period_s:g})"

    return LiveGraphView


def live_graph(rt=None, period_s: float = 1.0, include_hidden: bool = False, show_services: bool = False):
    """A widget showing the live ROS graph, redrawn every ``period_s`` seconds in the background.

    The kernel stays free: a background thread asks the graph and redraws only when
    it changed. Checkboxes toggle hidden infrastructure and services; "auto refresh"
    pauses the updates. Calling ``live_graph`` again (e.g. re-running the cell)
    stops the previous view's thread; ``view.close()`` or ``view.stop()`` stops it too.
    """
    import ipywidgets as w

    if isinstance(period_s, bool) or not isinstance(period_s, (int, float)) or not 0.2 <= period_s <= 60:
        raise CourseError(f"period_s must be a number of seconds between 0.2 and 60, got {period_s!r}")
    rt = _resolve_runtime(rt)
    stop_live_graphs("replaced by a newer live graph")

    image = w.Image(format="png", layout=w.Layout(max_width="100%"))
    hidden = w.Checkbox(value=include_hidden, description="show hidden", indent=False,
                        layout=w.Layout(width="auto"))
    services = w.Checkbox(value=show_services, description="show services", indent=False,
                          layout=w.Layout(width="auto"))
    auto = w.ToggleButton(value=True, description="auto refresh", icon="refresh",
                          tooltip=f"redraw every {period_s:g} s when the graph changes")
    refresh_button = w.Button(description="refresh now", layout=w.Layout(width="auto"))
    status = w.HTML()
    for control in (hidden, services, auto, refresh_button):
        control.layout.margin = "0 12px 0 0"
    controls = w.HBox([hidden, services, auto, refresh_button, status],
                      layout=w.Layout(align_items="center"))
    view = _view_class()([controls, image])
    view.period_s = float(period_s)
    view.image, view.hidden, view.services, view.auto = image, hidden, services, auto
    view.refresh_button, view.status, view.controls = refresh_button, status, controls
    view.controller = _LiveGraphController(rt, view, float(period_s))
    hidden.observe(lambda _change: view.controller.kick(), names="value")
    services.observe(lambda _change: view.controller.kick(), names="value")
    auto.observe(lambda _change: view.controller.kick(), names="value")
    refresh_button.on_click(lambda _button: view.controller.kick())
    with _live_lock:
        _live_views.append(view)
    view.controller.start()
    return view


def stop_live_graphs(reason: str = "stopped") -> None:
    """Stop every live graph refresher of this kernel."""
    with _live_lock:
        views = list(_live_views)
    for view in views:
        view.stop(reason)


def refresher_threads() -> list[threading.Thread]:
    """The live graph refresher threads still running (tests check there is at most one)."""
    return [t for t in threading.enumerate() if t.name == REFRESHER_THREAD_NAME and t.is_alive()]
