"""Drawing the graph picture with matplotlib, in a notebook figure or as PNG bytes.

Nodes are rounded boxes, topics rectangles; arrows go publisher -> topic -> subscriber and
carry the message type; services are dashed and actions pink.
"""

from __future__ import annotations

import io

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch, Patch

from course_helpers.core.errors import CourseError
from course_helpers.viz.layout import (
    EDGE_COLOUR,
    FONT_PT,
    LABEL_PT,
    PAD_IN,
    STYLE,
    TITLE_IN,
    Layout,
    Route,
    build_digraph,
    lay_out,
    text_width_in,
)
from course_helpers.viz.snapshot import GraphSnapshot, graph_snapshot


def _render(snap: GraphSnapshot, lay: Layout, ax, title: bool) -> None:
    ax.set_xlim(0, lay.width)
    ax.set_ylim(0, lay.height)
    ax.set_aspect("equal", adjustable="box")
    ax.axis("off")
    if title:
        ax.text(lay.width / 2, lay.height - TITLE_IN / 2, f"ROS graph (domain {snap.domain_id})",
                ha="center", va="center", fontsize=11 * lay.scale, fontweight="bold", gid="title")
    if not lay.vertices:
        ax.text(lay.width / 2, lay.height / 2, "no nodes in this domain yet", ha="center",
                va="center", fontsize=FONT_PT * lay.scale, color="#6b7280", style="italic")
        return
    for kind, name in lay.vertices:
        style, face, edge, line = STYLE[kind]
        (x, y), (hw, hh) = lay.pos[kind, name], lay.half[kind, name]
        ax.add_patch(FancyBboxPatch((x - hw + PAD_IN, y - hh + PAD_IN), 2 * (hw - PAD_IN),
                                    2 * (hh - PAD_IN), boxstyle=style.format(pad=PAD_IN),
                                    facecolor=face, edgecolor=edge, linestyle=line, linewidth=1.3 * lay.scale,
                                    zorder=3, gid=f"{kind}:{name}"))
        ax.text(x, y, name, ha="center", va="center", fontsize=FONT_PT * lay.scale, zorder=4,
                fontweight="bold" if kind == "node" else "normal", gid=f"label:{kind}:{name}")
    taken = [(lay.pos[v][0], lay.pos[v][1], *lay.half[v]) for v in lay.vertices]  # centre, half sizes
    for index, route in enumerate(lay.routes):
        _draw_route(ax, lay, index, route, taken)
    kinds = sorted({kind for kind, _name in lay.vertices}, key=list(STYLE).index)
    handles = [Patch(facecolor=STYLE[k][1], edgecolor=STYLE[k][2], linestyle=STYLE[k][3], label=k)
               for k in kinds]
    ax.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=LABEL_PT * lay.scale,
              frameon=False, bbox_to_anchor=(0.5, 0.0), handlelength=1.6)


def _draw_route(ax, lay: Layout, index: int, route: Route, taken: list) -> None:
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
    colour = EDGE_COLOUR[route.kind]
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
    half_w, half_h = text_width_in(route.label, LABEL_PT) / 2 + 0.05, LABEL_PT / 72 / 2 + 0.04

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
    ax.text(x, y, route.label, ha="center", va="center", fontsize=LABEL_PT * lay.scale, color=colour,
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
    lay = lay_out(build_digraph(snapshot, show_services, show_actions), orientation)
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
    lay = lay_out(build_digraph(snapshot, show_services, show_actions), _checked_orientation(orientation))
    fig = Figure(figsize=(lay.width, lay.height))
    FigureCanvasAgg(fig)
    _render(snapshot, lay, fig.add_axes((0, 0, 1, 1)), title=True)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()
