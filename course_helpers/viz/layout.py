"""Where each box and arrow of the graph picture goes: a deterministic layered layout.

``lay_out(build_digraph(snapshot, ...))`` puts nodes and topics in layers that run left to
right (or top to bottom when the picture would be too wide for a notebook), orders each layer
to reduce crossings, and routes long edges through the layers between their ends.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

import networkx as nx
from matplotlib.font_manager import FontProperties
from matplotlib.textpath import TextToPath

from course_helpers.viz.snapshot import GraphSnapshot

FONT_PT = 9.0        # names in boxes
LABEL_PT = 7.0       # edge labels (types)
PAD_IN = 0.10        # space between a name and its box
ROW_IN = 0.62        # vertical slot of a box in its column
DUMMY_IN = 0.30      # vertical slot of an edge passing through a column
MARGIN_IN = 0.35
TITLE_IN = 0.45
LEGEND_IN = 0.35
PART_GAP_IN = 0.15   # extra space between unconnected parts of the graph
PORT_IN = 0.055      # distance between arrows leaving or entering one side of a box
PORT_TB_IN = 0.12    # the same on the top and bottom sides (top-down layout)
LAYER_GAP_TB_IN = 0.7   # between layers of a top-down layout (room for a label)
SIBLING_GAP_TB_IN = 0.3  # between boxes side by side in a top-down layout
NOTEBOOK_IN = 13.0   # wider than this, a notebook shrinks the picture: try top-down instead

STYLE = {  # kind: (box style, face colour, edge colour, line style)
    "node": ("round,pad={pad},rounding_size=0.12", "#dbeafe", "#1d4ed8", "-"),
    "topic": ("square,pad={pad}", "#fef9c3", "#a16207", "-"),
    "service": ("square,pad={pad}", "#ede9fe", "#6d28d9", "--"),
    "action": ("round4,pad={pad}", "#fce7f3", "#be185d", "-"),
}
EDGE_COLOUR = {"topic": "#374151", "service": "#6d28d9", "action": "#be185d"}
DUMMY = "~edge"      # kind of the invisible points long edges pass through

_text_to_path = TextToPath()


def text_width_in(text: str, size_pt: float, bold: bool = False) -> float:
    font = FontProperties(size=size_pt, weight="bold" if bold else "normal")
    width, _height, _descent = _text_to_path.get_text_width_height_descent(text, font, ismath=False)
    return width / 72.0


def build_digraph(snap: GraphSnapshot, show_services: bool, show_actions: bool) -> nx.DiGraph:
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
class Route:
    """How one edge is drawn: the vertices it passes, left to right, and its direction."""

    src: tuple
    dst: tuple
    chain: list        # [left end, dummies..., right end]
    forward: bool      # False: drawn right to left (a back edge of a cycle)
    kind: str
    label: str


@dataclass
class Layout:
    vertices: list     # real vertices (kind, name), sorted
    pos: dict          # vertex or dummy -> (x, y) in inches
    half: dict         # vertex -> (half width, half height) of its box; dummies: half the layer's depth
    routes: list
    ports: dict        # (route index, vertex, "out" | "in") -> offset where the edge meets that box
    width: float
    height: float
    orientation: str   # "LR": layers left to right; "TB": top to bottom
    scale: float = 1.0  # font and line scale, below 1 when drawn into smaller axes


def lay_out(g: nx.DiGraph, orientation: str = "auto") -> Layout:
    """Place every box: layers along the flow, then an order across it that avoids crossings."""
    if orientation == "auto":  # left to right, unless too wide for a notebook and top-down is narrower
        wide = lay_out(g, "LR")
        if wide.width <= NOTEBOOK_IN:
            return wide
        tall = lay_out(g, "TB")
        return tall if tall.width < wide.width else wide
    lr = orientation == "LR"
    layer = _layers(g)
    routes = []
    for src, dst, data in sorted(g.edges(data=True)):
        forward = layer[dst] > layer[src]
        first, last = (src, dst) if forward else (dst, src)
        dummies = [(DUMMY, f"{src}>{dst}#{col:04d}") for col in range(layer[first] + 1, layer[last])]
        for col, dummy in zip(range(layer[first] + 1, layer[last]), dummies, strict=True):
            layer[dummy] = col
        routes.append(Route(src, dst, [first, *dummies, last], forward, data["kind"],
                             " / ".join(data["types"])))
    neighbours: dict = {v: [] for v in layer}
    for route in routes:
        for a, b in pairwise(route.chain):
            neighbours[a].append(b)
            neighbours[b].append(a)
    half = {}
    for v in g.nodes:
        half[v] = (text_width_in(v[1], FONT_PT, bold=v[0] == "node") / 2 + PAD_IN,
                   FONT_PT / 72 / 2 + PAD_IN)
    if lr:  # room for a type label between two layers
        gap = max(0.9, max((text_width_in(r.label, LABEL_PT) for r in routes), default=0.4) + 0.45)
    else:
        gap = LAYER_GAP_TB_IN

    label_half = {}  # top-down: the labels of a vertex's outgoing edges sit beside it
    for route in routes:
        source = route.src if route.forward else route.chain[-1]
        label_half[source] = max(label_half.get(source, 0.0), text_width_in(route.label, LABEL_PT) / 2)

    def slot(v):  # room a vertex takes across the flow
        if v[0] == DUMMY:
            return DUMMY_IN
        return ROW_IN if lr else 2 * max(half[v][0], label_half.get(v, 0.0)) + SIBLING_GAP_TB_IN

    # Lay out each connected part on its own and stack the parts across the flow, largest first.
    across = {}
    edge = 0.0
    for part in _connected_parts(neighbours):
        part_columns = _order_columns({v: layer[v] for v in part}, neighbours)
        part_across = _vertical_positions(part_columns, neighbours, slot)
        part_top = max(part_across[v] + slot(v) / 2 for v in part)
        for v in part:
            across[v] = part_across[v] - part_top + edge
        edge = min(across[v] - slot(v) / 2 for v in part) - PART_GAP_IN

    columns: list[list] = [[] for _ in range(max(layer.values(), default=-1) + 1)]
    for v in sorted(layer):
        columns[layer[v]].append(v)
    pos = {}
    depth = 0.0
    for column in columns:
        thick = max((half[v][0 if lr else 1] for v in column if v[0] != DUMMY), default=0.05)
        for v in column:
            pos[v] = (depth + thick, across[v]) if lr else (-across[v], -(depth + thick))
            if v[0] == DUMMY:
                half[v] = (thick, 0.0) if lr else (0.0, thick)
        depth += 2 * thick + gap

    # Fit the drawing between the margins, the title above and the legend below.
    xs = [c for v in pos for c in (pos[v][0] - half[v][0], pos[v][0] + half[v][0])] or [0.0, 1.0]
    ys = [c for v in pos for c in (pos[v][1] - half[v][1], pos[v][1] + half[v][1])] or [0.0, 1.0]
    dx, dy = MARGIN_IN - min(xs), LEGEND_IN + MARGIN_IN / 2 - min(ys)
    pos = {v: (x + dx, y + dy) for v, (x, y) in pos.items()}
    width = max(max(xs) - min(xs) + 2 * MARGIN_IN, 4.0)
    height = max(ys) - min(ys) + TITLE_IN + LEGEND_IN + MARGIN_IN
    if width > max(xs) - min(xs) + 2 * MARGIN_IN:  # centre a narrow drawing
        pos = {v: (x + (width - (max(xs) - min(xs)) - 2 * MARGIN_IN) / 2, y) for v, (x, y) in pos.items()}
    # Whole quarter inches keep the figure's text repr short and stable.
    width, height = math.ceil(width * 4) / 4, math.ceil(height * 4) / 4
    return Layout(sorted(g.nodes), pos, half, routes, _ports(routes, pos, half, lr), width, height,
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
        step_in, room = (PORT_IN, half[vertex][1]) if lr else (PORT_TB_IN, half[vertex][0])
        spread = min(step_in * (len(entries) - 1) / 2, 0.7 * room)
        step = 2 * spread / (len(entries) - 1) if len(entries) > 1 else 0.0
        for i, (_across, index) in enumerate(entries):
            offset = spread - i * step
            ports[index, vertex, side] = offset if lr else -offset
    return ports
