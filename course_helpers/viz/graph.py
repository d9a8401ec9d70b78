"""The live ROS computation graph, drawn like rqt_graph.

* :func:`graph_snapshot` returns the graph as plain data (nodes, topics, edges labelled with
  their types, services and actions);
* :func:`draw_graph` draws it with matplotlib: nodes as rounded boxes, topics as rectangles,
  arrows publisher -> topic -> subscriber, laid out in deterministic layers;
* :func:`live_graph` shows a widget that redraws the picture while the notebook keeps running.

The work is split by job: :mod:`.snapshot` (asking the graph), :mod:`.layout` (placing boxes),
:mod:`.render` (drawing) and :mod:`.live` (the refreshing widget).
"""

from course_helpers.viz.live import REFRESHER_THREAD_NAME, live_graph, refresher_threads, stop_live_graphs
from course_helpers.viz.render import draw_graph, render_png
from course_helpers.viz.snapshot import (
    Edge,
    GraphSnapshot,
    graph_snapshot,
    is_hidden_node,
    is_hidden_service,
    is_hidden_topic,
    short_type,
    snapshot_of,
)

__all__ = ["REFRESHER_THREAD_NAME", "Edge", "GraphSnapshot", "draw_graph", "graph_snapshot",
           "is_hidden_node", "is_hidden_service", "is_hidden_topic", "live_graph", "refresher_threads",
           "render_png", "short_type", "snapshot_of", "stop_live_graphs"]
