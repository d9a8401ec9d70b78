"""The computation-graph view (course_helpers.viz.graph) against the live graph of real nodes."""

from __future__ import annotations

import threading
import time

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import pytest
from matplotlib.figure import Figure
from rclpy.action import ActionClient, ActionServer
from std_msgs.msg import String
from test_msgs.action import Fibonacci

from course_helpers import CourseError, get_runtime
from course_helpers.core.waiting import wait_until
from course_helpers.nodes import Listener, Talker, make_relay
from course_helpers.viz.graph import (
    REFRESHER_THREAD_NAME,
    Edge,
    GraphSnapshot,
    draw_graph,
    graph_snapshot,
    is_hidden_service,
    is_hidden_topic,
    live_graph,
    refresher_threads,
    short_type,
    stop_live_graphs,
)

from .conftest import REPO
from .kernel_session import KernelSession

EXPECTED = {
    ("/talker", "/chatter", "std_msgs/msg/String"),
    ("/chatter", "/listener", "std_msgs/msg/String"),
    ("/chatter", "/relay", "std_msgs/msg/String"),  # the relay runs in a child process
    ("/relay", "/chatter_relayed", "std_msgs/msg/String"),
    ("/chatter_relayed", "/relay_listener", "std_msgs/msg/String"),
}


# rmw_dds_common's name for an endpoint whose participant is known but whose entity list names no node
# of it (graph_cache.cpp, UNDISCOVERED_ROS_NODE): the endpoint's DDS discovery and its participant's
# ros_discovery_info message arrive apart, so the per-topic view may hold one that no node owns
UNATTRIBUTED_NODE = "_NODE_NAME_UNKNOWN_"


def live_edges(rt, include_hidden: bool, unattributed: set | None = None) -> set[tuple[str, str, str]]:
    """Edges derived independently, topic by topic, from the endpoints the middleware reports.

    A snapshot is built node by node, so an endpoint the middleware names no node for is none of its
    business: such endpoints go into ``unattributed`` (printed when the views disagree), not the edges.
    """
    edges = set()
    for topic, _types in rt.graph.get_topic_names_and_types():
        if is_hidden_topic(topic) and not include_hidden:
            continue
        for query, publishes in ((rt.graph.get_publishers_info_by_topic, True),
                                 (rt.graph.get_subscriptions_info_by_topic, False)):
            for info in query(topic):
                fqn = info.node_namespace.rstrip("/") + "/" + info.node_name
                edge = (fqn, topic, info.topic_type) if publishes else (topic, fqn, info.topic_type)
                if info.node_name == UNATTRIBUTED_NODE:
                    if unattributed is not None:
                        unattributed.add(edge)
                elif include_hidden or not info.node_name.startswith("_"):
                    edges.add(edge)
    return edges


def snapshot_edges(snap: GraphSnapshot) -> set[tuple[str, str, str]]:
    return {(e.source, e.target, e.type) for e in snap.edges}


def settle(rt, include_hidden: bool) -> GraphSnapshot:
    """Wait until the snapshot and the per-topic view agree (discovery is asynchronous)."""
    found = {}

    def agree():
        found["snap"] = graph_snapshot(rt, include_hidden=include_hidden)
        found["unattributed"] = set()
        found["live"] = live_edges(rt, include_hidden, found["unattributed"])
        return snapshot_edges(found["snap"]) == found["live"] and EXPECTED <= found["live"]

    try:
        rt.wait_until(agree, 30, "the graph snapshot to match the live graph")
    except Exception:
        snap_only = snapshot_edges(found["snap"]) - found["live"]
        live_only = found["live"] - snapshot_edges(found["snap"])
        pytest.fail(f"snapshot-only edges {sorted(snap_only)}; live-only edges {sorted(live_only)}; "
                    f"endpoints no node owns (left out of both) {sorted(found['unattributed'])}")
    return found["snap"]


@pytest.fixture
def world(rt):
    """Talker and listeners in this process, a relay in a child process."""
    rt.add(Talker, rate_hz=5)
    rt.add(Listener)
    rt.add(Listener, name="relay_listener", topic="chatter_relayed")
    rt.spawn("relay", make_relay, wait_for="/relay")
    yield rt
    stop_live_graphs()
    plt.close("all")


def test_snapshot_edges_match_the_live_graph(world):
    snap = settle(world, include_hidden=False)
    assert snapshot_edges(snap) == live_edges(world, include_hidden=False)
    assert EXPECTED <= snapshot_edges(snap)
    assert {"/talker", "/listener", "/relay", "/relay_listener"} <= set(snap.nodes)
    assert snap.topics["/chatter"] == ["std_msgs/msg/String"]
    assert snap.publishers("/chatter") == ["/talker"]
    assert snap.subscribers("/chatter") == ["/listener", "/relay"]
    assert snap.domain_id == world.domain.domain_id
    assert snap.nodes == sorted(snap.nodes) and snap.edges == sorted(snap.edges)
    assert "/talker -> /chatter [std_msgs/String]" in snap.as_text().splitlines()


def test_hidden_names_are_left_out_unless_asked_for(world):
    node = world.node("fib_server")
    node.action_server = ActionServer(node, Fibonacci, "fibonacci", lambda goal: Fibonacci.Result())
    client = world.node("fib_client")
    client.action_client = ActionClient(client, Fibonacci, "fibonacci")
    world.wait_until(lambda: len(graph_snapshot(world).action_edges) == 2, 10, "the action in the graph")

    plain = settle(world, include_hidden=False)
    assert not [n for n in plain.nodes if n.rsplit("/", 1)[-1].startswith("_")]
    assert not [t for t in plain.topics if is_hidden_topic(t)]
    assert not [s for s in plain.services if is_hidden_service(s)]
    assert "/rosout" not in plain.topics and "/parameter_events" not in plain.topics
    assert plain.actions == {"/fibonacci": ["test_msgs/action/Fibonacci"]}
    assert {(e.source, e.target) for e in plain.action_edges} == {
        ("/fib_client", "/fibonacci"), ("/fibonacci", "/fib_server")}

    full = settle(world, include_hidden=True)
    assert snapshot_edges(full) == live_edges(world, include_hidden=True)
    assert "/_course_runtime" in full.nodes
    assert {"/rosout", "/parameter_events", "/fibonacci/_action/status"} <= set(full.topics)
    assert "/fibonacci/_action/send_goal" in full.services
    assert "/talker/get_parameters" in full.services
    assert snapshot_edges(plain) < snapshot_edges(full)


def test_services_are_listed_with_clients_and_servers(rt):
    from test_msgs.srv import Empty

    server = rt.node("resetter")
    server.service = server.create_service(Empty, "reset", lambda request, response: response)
    caller = rt.node("caller")
    caller.client = caller.create_client(Empty, "reset")
    rt.wait_until(lambda: len(graph_snapshot(rt).service_edges) == 2, 10, "the service in the graph")
    snap = graph_snapshot(rt)
    assert snap.services == {"/reset": ["test_msgs/srv/Empty"]}
    assert {(e.source, e.target, e.role) for e in snap.service_edges} == {
        ("/caller", "/reset", "client"), ("/reset", "/resetter", "server")}


def test_draw_graph_draws_each_node_and_topic_once(world):
    snap = settle(world, include_hidden=False)
    assert isinstance(draw_graph(world), Figure)
    # The picture of one snapshot (the live graph may gain a node between two snapshots).
    fig = draw_graph(snapshot=snap)
    ax = fig.axes[0]
    boxes = sorted(p.get_gid() for p in ax.patches if (p.get_gid() or "").split(":")[0] in ("node", "topic"))
    expected = sorted([f"node:{n}" for n in snap.nodes] + [f"topic:{t}" for t in snap.topics])
    assert boxes == expected
    texts = [t.get_text() for t in ax.texts]
    for name in [*snap.nodes, *snap.topics]:
        assert texts.count(name) == 1, name
    labels = [t.get_text() for t in ax.texts if t.get_gid() == "edge-label"]
    assert labels.count("std_msgs/String") == len(snap.edges)
    assert f"ROS graph (domain {world.domain.domain_id})" in texts

    # Deterministic: the same graph gives the same picture.
    again = draw_graph(snapshot=snap)
    assert [(t.get_text(), t.get_position()) for t in again.axes[0].texts] == \
        [(t.get_text(), t.get_position()) for t in ax.texts]
    assert tuple(fig.get_size_inches()) == tuple(again.get_size_inches())

    # Left to right: publishers, their topic, its subscribers; top to bottom when asked.
    left_right = {t.get_text(): t.get_position()
                  for t in draw_graph(snapshot=snap, orientation="LR").axes[0].texts}
    top_down = {t.get_text(): t.get_position()
                for t in draw_graph(snapshot=snap, orientation="TB").axes[0].texts}
    for chain in (["/talker", "/chatter", "/listener"], ["/relay", "/chatter_relayed", "/relay_listener"]):
        assert [left_right[name][0] for name in chain] == sorted(left_right[name][0] for name in chain)
        assert [top_down[name][1] for name in chain] == sorted((top_down[name][1] for name in chain),
                                                               reverse=True)
    with pytest.raises(CourseError, match="orientation"):
        draw_graph(snapshot=snap, orientation="sideways")


def test_draw_graph_shows_hidden_topics_and_services_on_request(world):
    settle(world, include_hidden=True)
    fig = draw_graph(world, include_hidden=True, show_services=True)
    gids = {p.get_gid() for p in fig.axes[0].patches}
    assert {"topic:/rosout", "node:/_course_runtime", "service:/talker/get_parameters"} <= gids
    fig, ax = plt.subplots(figsize=(6, 3))
    assert draw_graph(world, ax=ax) is fig
    assert ax.get_title().startswith("ROS graph (domain ")


def test_drawing_a_graph_with_a_cycle_and_an_empty_graph():
    edges = [Edge("/ping", "/ping", "std_msgs/msg/Int32", "topic", "publisher"),
             Edge("/ping", "/pong", "std_msgs/msg/Int32", "topic", "subscriber"),
             Edge("/pong", "/pong", "std_msgs/msg/Int32", "topic", "publisher"),
             Edge("/pong", "/ping", "std_msgs/msg/Int32", "topic", "subscriber")]
    snap = GraphSnapshot(1, nodes=["/ping", "/pong", "/lonely"],
                         topics={"/ping": ["std_msgs/msg/Int32"], "/pong": ["std_msgs/msg/Int32"]},
                         edges=sorted(edges))
    fig = draw_graph(snapshot=snap)  # a node and a topic may share a name
    gids = sorted(p.get_gid() for p in fig.axes[0].patches if p.get_gid())
    assert gids == ["node:/lonely", "node:/ping", "node:/pong", "topic:/ping", "topic:/pong"]
    empty = draw_graph(snapshot=GraphSnapshot(1))
    assert "no nodes in this domain yet" in [t.get_text() for t in empty.axes[0].texts]
    plt.close("all")


def test_names_and_types():
    assert short_type("std_msgs/msg/String") == "std_msgs/String"
    assert short_type("test_msgs/action/Fibonacci") == "test_msgs/Fibonacci"
    assert is_hidden_topic("/rosout") and is_hidden_topic("/fib/_action/status")
    assert not is_hidden_topic("/chatter")
    assert is_hidden_service("/talker/set_parameters") and is_hidden_service("/x/_action/send_goal")
    assert not is_hidden_service("/add_two_ints")


def test_live_graph_keeps_one_refresher_and_stops_when_closed(world):
    settle(world, include_hidden=False)
    first = live_graph(world, period_s=0.2)
    second = live_graph(world, period_s=0.2)  # like re-running the cell
    assert len(refresher_threads()) == 1
    assert not first.controller.running and second.controller.running
    world.wait_until(lambda: bytes(second.image.value).startswith(b"\x89PNG"), 10, "a drawn graph")
    redraws = second.controller.redraws
    world.add(Listener, name="late_listener")  # the graph changes: the picture follows
    world.wait_until(lambda: second.controller.redraws > redraws, 10, "a redraw after a change")
    second.hidden.value = True
    world.wait_until(lambda: second.controller.redraws > redraws + 1, 10, "a redraw with hidden names")
    assert repr(second) == "LiveGraphView(period_s=0.2)"
    second.close()
    assert refresher_threads() == []
    assert not [t for t in threading.enumerate() if t.name == REFRESHER_THREAD_NAME]


def test_live_graph_rejects_a_bad_period(rt):
    with pytest.raises(CourseError, match="period_s"):
        live_graph(rt, period_s=0)
    with pytest.raises(CourseError, match="runtime"):
        graph_snapshot("not a runtime")


def test_live_graph_follows_a_changing_graph(rt):
    view = live_graph(rt, period_s=0.2)
    try:
        publisher_node = rt.node("pulse")
        publisher_node.pub = publisher_node.create_publisher(String, "pulse", 10)
        rt.wait_until(lambda: "/pulse" in graph_snapshot(rt).topics, 10, "/pulse in the graph")
        rt.wait_until(lambda: view.controller.snapshot is not None
                      and "/pulse" in view.controller.snapshot.topics, 10, "/pulse in the picture")
        assert "topic" in view.status.value
    finally:
        view.close()
    assert refresher_threads() == []


def test_live_graph_updates_a_kernel_while_it_is_idle():
    """In a real kernel the picture is sent from the refresher thread, and re-running keeps one thread."""
    kernel = KernelSession(cwd=REPO)
    try:
        setup = ("from course_helpers import get_runtime\n"
                 "from course_helpers.viz.graph import live_graph, refresher_threads\n"
                 "rt = get_runtime()\n")
        cell = "view = live_graph(period_s=0.3)\nview"
        assert kernel.run(setup)[1] is None
        assert kernel.run(cell) == ("LiveGraphView(period_s=0.3)", None)
        assert kernel.run(cell) == ("LiveGraphView(period_s=0.3)", None)  # the cell re-run
        assert kernel.run("from course_helpers.nodes import Talker\nrt.add(Talker, console=False)\n"
                          "print(len(refresher_threads()))") == ("1\n", None)
        images = 0
        deadline = time.monotonic() + 10
        while images == 0 and time.monotonic() < deadline:  # the kernel is idle now
            try:
                msg = kernel.client.get_iopub_msg(timeout=0.3)
            except Exception:
                continue
            if msg["msg_type"] == "comm_msg" and msg.get("buffers"):
                images += 1  # an Image widget's new PNG travels as a binary buffer
        assert images >= 1
        assert kernel.run("view.close()\nprint(len(refresher_threads()))") == ("0\n", None)
    finally:
        kernel.shutdown()


def test_live_graph_never_restarts_a_stopped_runtime(rt):
    view = live_graph(rt, period_s=0.2)
    try:
        rt.wait_until(lambda: view.controller.snapshot is not None, 10, "a first picture")
        rt.stop()
        rt.wait_until(lambda: "runtime stopped" in view.status.value, 5, "the view to notice")
        looked = view.controller.refreshes
        wait_until(lambda: view.controller.refreshes >= looked + 3, 10, "three more refreshes")
        assert not rt.running
    finally:
        view.close()
        get_runtime()  # the next tests need it running again


def test_a_graph_too_wide_for_a_notebook_is_drawn_top_down():
    names = [f"/stage_{i}_with_a_descriptive_name" for i in range(7)]
    edges = []
    for i, (node, nxt) in enumerate(zip(names, names[1:], strict=False)):
        edges += [Edge(node, f"/link_{i}", "geometry_msgs/msg/PoseStamped", "topic", "publisher"),
                  Edge(f"/link_{i}", nxt, "geometry_msgs/msg/PoseStamped", "topic", "subscriber")]
    snap = GraphSnapshot(1, nodes=sorted(names), topics={f"/link_{i}": ["geometry_msgs/msg/PoseStamped"]
                                                         for i in range(6)}, edges=sorted(edges))
    wide = draw_graph(snapshot=snap, orientation="LR").get_size_inches()
    auto = draw_graph(snapshot=snap).get_size_inches()
    assert wide[0] > 13 and auto[0] < wide[0] and auto[1] > wide[1]
    plt.close("all")
