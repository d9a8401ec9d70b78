"""The runtime's view of the graph against ghosts: nodes rmw lists under a name with no live endpoint.

A process that ends its node and its participant at once can leave such a ghost in another process's
graph cache (course_helpers/core/child.py). rmw answers a query *by node name* from the first node of
that name it finds, so a ghost could hide a live node of the same name for good: chapter 09's package
run again after Ctrl+C never seemed to appear. A node without endpoints (``bare_node``) is listed the
same way a ghost is, and makes the situation certain: with the bare node in either process, the live
node's endpoints must show. One of the two orders fails with rcl's by-name queries.
"""

from __future__ import annotations

import pytest

from course_helpers.core.node_hook import bare_node
from course_helpers.nodes import Talker
from tests.helpers_children import hold_a_bare_node

NAME = "twin"


def _listed(rt) -> bool:
    return NAME in [name for name, _ in rt.graph.get_node_names_and_namespaces()]


@pytest.mark.parametrize("bare_in", ["child", "kernel"])
def test_a_name_listed_without_endpoints_does_not_hide_the_live_node(rt, bare_in):
    if bare_in == "child":
        rt.spawn("bare_twin", hold_a_bare_node, {"name": NAME}).wait_for_report("ready", 30, "the bare node")
        rt.wait_until(lambda: _listed(rt), 30, "the graph to list the bare node")
        assert f"/{NAME}" not in rt.graph_nodes()  # listed by rmw, but nothing live: not a node of the graph
        rt.add(Talker, name=NAME, topic="twin_chatter", console=False)
    else:
        keeper = bare_node(rt.context, NAME)
        rt.spawn("live_twin", "course_helpers.nodes:make_talker", {"name": NAME, "topic": "twin_chatter"},
                 wait_for=f"/{NAME}")  # waits for the live node's endpoints to settle
    try:
        rt.wait_until(lambda: f"/{NAME}" in rt.graph_nodes(), 30, "the live twin")
        publishers = rt._graph_view().entry(f"/{NAME}")[0]
        assert "/twin_chatter std_msgs/msg/String" in publishers, publishers  # spelled as ROS spells it
    finally:
        if bare_in == "kernel":
            keeper.destroy_when_not_in_use()
