"""Contexts made once per process and kept: a DDS participant that the course would otherwise make and
destroy again and again is never destroyed while the process runs.

Why: with the Fast DDS 2.14.5 of the PyPI wheels, destroying a participant can hang the process for good.
rmw_fastrtps destroys a context's participant with the context's last node (``rmw_destroy_node`` ->
``decrement_context_impl_ref_count`` -> ``destroy_participant``), which first calls
``DomainParticipant::set_listener(nullptr)`` with the default, endless timeout. ``set_listener`` waits
for any discovery callback of the participant's listener that is running, and with that endless
timeout its ``condition_variable::wait_until`` never blocks: it spins while holding the very mutex the
running callback must take to end (eProsima/Fast-DDS#6513; ``DomainParticipantImpl.hpp``). Fresh-clone
run B on ``f577be2`` hung that way for more than 15 minutes, in a chapter 04 sandbox's close, with the
GIL held (so no Python timeout could fire) and Fast DDS's discovery thread waiting on that mutex.

A new participant discovers every endpoint already in its domain, in a burst of such callbacks, so one
destroyed soon after it was made is the likeliest to meet one. The course's sandboxes were exactly
that. A kept context is made at its first use and then holds its participant through a hidden node
(leading underscore: ``rt.graph_nodes()`` and ``ros2 node list`` leave it out), so the nodes built and
destroyed in it never take the participant down with them.

The keeper is a bare rcl node, without a single endpoint (:func:`.node_hook.bare_node`, as a child
process's keeper is). An rclpy ``Node`` would add a ``/parameter_events`` writer, announced apart from
the ``ros_discovery_info`` update that names its node: the project's CI on ``3d681dd`` met a kernel
whose graph kept such a writer under ``_NODE_NAME_UNKNOWN_`` for more than a minute. The bare keeper's
first update is also its last, and it is no ``Node`` for ``rt.status()`` to count.
"""

from __future__ import annotations

import threading

from rclpy.context import Context

from course_helpers.core.dds_config import init_context
from course_helpers.core.node_hook import bare_node

KEEPER_NODE = "_course_kept_participant"
_kept: dict[tuple[int, str], tuple[Context, object]] = {}  # the context and its keeper
_lock = threading.Lock()


def kept_context(domain_id: int, namespace: str) -> Context:
    """This process's context for ``domain_id`` whose nodes all live in ``namespace`` (a global remapping,
    so that their names never clash with the kernel's own), made at the first call and kept after."""
    key = (domain_id, namespace)
    with _lock:
        if key in _kept and _kept[key][0].ok():
            return _kept[key][0]
        context = Context()
        init_context(context, domain_id, ["--ros-args", "--disable-stdout-logs", "-r", f"__ns:={namespace}"])
        _kept[key] = (context, bare_node(context, KEEPER_NODE, namespace))
        return context
