"""Checker of chapter 10 (capstone): validate a robot design against the running robot.

The student describes the warehouse robot as a dict: its nodes, and for every
channel the type, who publishes/subscribes (serves/calls), and for topics the
QoS. :func:`check_design` compares that design with the live ROS graph:

* every declared node runs, every declared channel exists with the declared type
  and the declared endpoints;
* the declared QoS is compatible with the endpoints that really run (reliability
  and durability; the history depth is local to each endpoint and not checked);
* the e-stop is RELIABLE + TRANSIENT_LOCAL, and a subscriber created now with the
  declared e-stop QoS (a late joiner) still receives the current e-stop state;
* data flows on each declared sensor topic to a subscriber with the declared QoS.

Design format (names are relative to ``namespace``)::

    {'namespace': '/robot1',
     'nodes': ['camera', 'base', ...],
     'topics': [{'name': 'camera/image_raw', 'type': 'sensor_msgs/msg/Image',
                 'publishers': ['camera'], 'subscribers': [],
                 'qos': {'reliability': 'best_effort', 'durability': 'volatile', 'depth': 5}}, ...],
     'services': [{'name': 'pick_item', 'type': 'course_interfaces/srv/PickItem',
                   'server': 'gripper', 'clients': ['mission_runner']}],
     'actions': [{'name': 'navigate', 'type': 'course_interfaces/action/Navigate',
                  'server': 'navigator', 'clients': ['mission_runner']}]}

A topic may add ``'subscriber_qos'`` when its readers use other settings than its writers.
"""

from __future__ import annotations

from functools import partial

from rclpy.action.graph import (
    get_action_client_names_and_types_by_node,
    get_action_names_and_types,
    get_action_server_names_and_types_by_node,
)
from rclpy.qos import QoSProfile

from course_helpers.chapters.ch10_capstone import endpoint_qos
from course_helpers.checks import CheckReport
from course_helpers.core.errors import CourseError, WaitTimeout
from course_helpers.core.names import full_name, split_full_name
from course_helpers.core.qos_dict import qos_from_dict, qos_to_dict
from course_helpers.core.validation import interface_name, resolve_interface

# Every interface the warehouse robot uses must appear in a design.
REQUIRED_TYPES = {
    "sensor_msgs/msg/Image": "the camera stream",
    "sensor_msgs/msg/LaserScan": "the LIDAR scan",
    "nav_msgs/msg/Odometry": "odometry",
    "geometry_msgs/msg/Twist": "velocity commands",
    "course_interfaces/msg/EStop": "the e-stop",
    "course_interfaces/srv/PickItem": "the pick service",
    "course_interfaces/action/Navigate": "the navigation action",
}
SENSOR_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry")
RELIABILITIES = ("reliable", "best_effort")  # what a design may write
DURABILITIES = ("volatile", "transient_local")
QOS_HINT = ("QoS is a dict like {'reliability': 'reliable' or 'best_effort', "
            "'durability': 'volatile' or 'transient_local', 'depth': 10}")


def qos_from_spec(spec) -> QoSProfile:
    """A KEEP_LAST QoSProfile from a design's QoS dict, or the profile itself if given one.

    Raises CourseError naming what is allowed when a key or a value is not.
    """
    if isinstance(spec, QoSProfile):
        return spec
    if not isinstance(spec, dict):
        raise CourseError(f"{QOS_HINT}; got {spec!r}")
    unknown = set(spec) - {"reliability", "durability", "depth"}
    if unknown:
        raise CourseError(f"unknown QoS keys {sorted(unknown)}; {QOS_HINT}")
    reliability = str(spec.get("reliability", "reliable")).lower()
    durability = str(spec.get("durability", "volatile")).lower()
    if reliability not in RELIABILITIES:
        raise CourseError(f"reliability must be 'reliable' or 'best_effort', got {reliability!r}")
    if durability not in DURABILITIES:
        raise CourseError(f"durability must be 'volatile' or 'transient_local', got {durability!r}")
    return qos_from_dict({"reliability": reliability, "durability": durability,
                          "depth": spec.get("depth", 10)})


def _policies(qos: QoSProfile) -> tuple[str, str]:
    """(reliability, durability) of a profile as the design writes them."""
    values = qos_to_dict(qos)
    return values["reliability"], values["durability"]


def incompatibility(writer: tuple[str, str], reader: tuple[str, str]) -> str:
    """Why a writer (reliability, durability) cannot serve a reader, or '' when it can.

    A reader may ask for less than a writer offers, never more: RELIABLE readers need
    RELIABLE writers, TRANSIENT_LOCAL readers need TRANSIENT_LOCAL writers.
    """
    problems = []
    if reader[0] == "reliable" and writer[0] == "best_effort":
        problems.append("a reliable reader cannot match a best_effort writer")
    if reader[1] == "transient_local" and writer[1] == "volatile":
        problems.append("a transient_local reader cannot match a volatile writer")
    return "; ".join(problems)


def check_design(design: dict, rt=None, late_joiner_timeout: float = 3.0) -> CheckReport:
    """Validate ``design`` against the running robot; see the module docstring."""
    from course_helpers.core.runtime import get_runtime

    rt = rt or get_runtime()
    report = CheckReport("Warehouse robot design vs the running system")
    parsed = _parse(report, design)
    if parsed is None:
        return report
    namespace, nodes, topics, services, actions = parsed

    running = set(rt.graph_nodes())
    missing = [n for n in nodes if _resolve(namespace, n) not in running]
    report.add(f"every declared node runs under {namespace}", not missing,
               f"not running: {', '.join(missing)}" if missing else f"{len(nodes)} nodes",
               f"Compare with %ros2 node list; names are relative to {namespace}.")

    declared_types = {t["type"] for t in topics} | {s["type"] for s in services} | {
        a["type"] for a in actions}
    absent = [f"{what} ({kind})" for kind, what in REQUIRED_TYPES.items() if kind not in declared_types]
    report.add("the design covers every channel the robot needs", not absent,
               f"missing: {', '.join(absent)}" if absent else "",
               "A warehouse robot needs its sensors, odometry, velocity commands, the e-stop, "
               "the pick service and the navigation action.")

    _check_topics(report, rt, namespace, topics)
    _check_servers(report, rt, namespace, services, "service")
    _check_servers(report, rt, namespace, actions, "action")
    _check_estop(report, rt, namespace, topics, late_joiner_timeout)
    _check_data_flows(report, rt, namespace, topics)
    return report


# ---------------------------------------------------------------------------------- parsing
def _parse(report: CheckReport, design):
    if not isinstance(design, dict):
        report.add("the design is a dict", False, f"got {type(design).__name__}",
                   "Start from the skeleton in the notebook: {'namespace': ..., 'nodes': [...], ...}.")
        return None
    problems = []
    namespace = design.get("namespace", "/robot1")
    if not isinstance(namespace, str) or not namespace.startswith("/"):
        problems.append(f"namespace must look like '/robot1', got {namespace!r}")
    nodes = design.get("nodes", [])
    if not isinstance(nodes, list) or not all(isinstance(n, str) for n in nodes):
        problems.append("nodes must be a list of node names")
        nodes = []
    topics, services, actions = [], [], []
    for index, topic in enumerate(_list(design, "topics", problems)):
        where = f"topic #{index + 1} ({topic.get('name', '?') if isinstance(topic, dict) else topic!r})"
        entry = _channel(topic, where, "msg", problems)
        if entry is None:
            continue
        entry["publishers"] = _names(topic.get("publishers", []), where, "publishers", problems)
        entry["subscribers"] = _names(topic.get("subscribers", []), where, "subscribers", problems)
        try:
            entry["qos"] = qos_from_spec(topic.get("qos"))
            entry["subscriber_qos"] = qos_from_spec(topic.get("subscriber_qos", topic.get("qos")))
        except CourseError as exc:
            problems.append(f"{where}: {exc}")
            continue
        topics.append(entry)
    for kind, target, bucket in (("services", "srv", services), ("actions", "action", actions)):
        for index, item in enumerate(_list(design, kind, problems)):
            label = item.get("name", "?") if isinstance(item, dict) else repr(item)
            where = f"{kind[:-1]} #{index + 1} ({label})"
            entry = _channel(item, where, target, problems)
            if entry is None:
                continue
            entry["server"] = item.get("server", "")
            entry["clients"] = _names(item.get("clients", []), where, "clients", problems)
            if not isinstance(entry["server"], str) or not entry["server"]:
                problems.append(f"{where}: 'server' must name the node that serves it")
                continue
            bucket.append(entry)
    report.add("the design is complete and well formed", not problems, "; ".join(problems[:4]),
               "Each topic needs name, type, publishers, subscribers and qos; each service and "
               "action needs name, type, server and clients. " + QOS_HINT)
    if not topics and not services and not actions:
        return None
    return namespace, nodes, topics, services, actions


def _list(design: dict, key: str, problems: list) -> list:
    value = design.get(key, [])
    if not isinstance(value, list):
        problems.append(f"'{key}' must be a list")
        return []
    return value


def _names(value, where: str, key: str, problems: list) -> list[str]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        problems.append(f"{where}: '{key}' must be a list of node names")
        return []
    return value


def _channel(item, where: str, kind: str, problems: list) -> dict | None:
    if not isinstance(item, dict) or not isinstance(item.get("name"), str) or not item.get("name"):
        problems.append(f"{where}: needs a 'name'")
        return None
    try:
        cls = resolve_interface(str(item.get("type", "")), kind)
    except CourseError:
        problems.append(f"{where}: type {item.get('type')!r} is not a known {kind} "
                        f"(write it like 'sensor_msgs/msg/Image')")
        return None
    return {"name": item["name"], "type": interface_name(cls)}


# ---------------------------------------------------------------------------------- the graph
def _check_topics(report, rt, namespace, topics) -> None:
    existing = dict(rt.graph.get_topic_names_and_types())
    wrong, endpoints, qos_problems = [], [], []
    for topic in topics:
        full = _resolve(namespace, topic["name"])
        types = existing.get(full)
        if not types:
            wrong.append(f"{full} does not exist")
            continue
        if topic["type"] not in types:
            wrong.append(f"{full} carries {', '.join(types)}, not {topic['type']}")
            continue
        live = endpoint_qos(rt, full)
        publishers = {node: (rel, dur) for node, rel, dur in live["publishers"]}
        subscribers = {node: (rel, dur) for node, rel, dur in live["subscriptions"]}
        for role, declared, actual in (("publish", topic["publishers"], publishers),
                                       ("subscribe to", topic["subscribers"], subscribers)):
            for name in declared:
                if _resolve(namespace, name) not in actual:
                    endpoints.append(f"{name} does not {role} {full}")
        design_writer = _policies(topic["qos"])
        design_reader = _policies(topic["subscriber_qos"])
        for node, writer in sorted(publishers.items()):
            why = incompatibility(writer, design_reader)
            if why:
                qos_problems.append(f"{full}: your readers vs {node} ({writer[0]}, {writer[1]}): {why}")
        for node, reader in sorted(subscribers.items()):
            why = incompatibility(design_writer, reader)
            if why and "/_" not in node:
                qos_problems.append(f"{full}: your writer vs {node} ({reader[0]}, {reader[1]}): {why}")
    report.add("every declared topic exists with the declared type", not wrong, "; ".join(wrong[:3]),
               "Check names and types with %ros2 topic list -t (names are relative to the namespace).")
    report.add("the declared publishers and subscribers are the real ones", not endpoints,
               "; ".join(endpoints[:3]), "Check who is on each topic with %ros2 topic info -v TOPIC.")
    report.add("the declared QoS is compatible with the endpoints that run", not qos_problems,
               "; ".join(qos_problems[:2]),
               "%ros2 topic info -v shows each endpoint's reliability and durability. A reader may "
               "ask for less than a writer offers, never more.")


def _check_servers(report, rt, namespace, entries, kind: str) -> None:
    """Check each declared service or action (``kind``): its type, its server and its clients."""
    if not entries:
        return
    if kind == "service":
        existing = dict(rt.graph.get_service_names_and_types())
        served_by = rt.graph.get_service_names_and_types_by_node
        called_by = rt.graph.get_client_names_and_types_by_node
        hint = "See %ros2 service list -t and %ros2 node info NODE."
    else:
        existing = dict(get_action_names_and_types(rt.graph))
        served_by = partial(get_action_server_names_and_types_by_node, rt.graph)
        called_by = partial(get_action_client_names_and_types_by_node, rt.graph)
        hint = "See %ros2 action list -t and %ros2 action info ACTION."
    problems = []
    for entry in entries:
        full = _resolve(namespace, entry["name"])
        if entry["type"] not in existing.get(full, []):
            problems.append(f"no {kind} {full} of type {entry['type']}")
            continue
        if full not in _names_by_node(served_by, _resolve(namespace, entry["server"])):
            problems.append(f"{entry['server']} does not serve {full}")
        for client in entry["clients"]:
            if full not in _names_by_node(called_by, _resolve(namespace, client)):
                problems.append(f"{client} is not a client of {full}")
    report.add(f"every declared {kind} exists with its server and clients", not problems,
               "; ".join(problems[:3]), hint)


def _names_by_node(query, node: str) -> dict:
    """``query(name, namespace)`` of the node with full name ``node`` as a dict; {} if there is none."""
    namespace, name = split_full_name(node)
    try:
        return dict(query(name, namespace))
    except RuntimeError:  # rclpy's RCLError: no such node, or not a valid node name
        return {}


def _check_estop(report, rt, namespace, topics, timeout: float) -> None:
    from course_interfaces.msg import EStop

    estops = [t for t in topics if t["type"] == "course_interfaces/msg/EStop"]
    if not estops:
        return
    topic = estops[0]
    writer, reader = topic["qos"], topic["subscriber_qos"]
    latched = all(_policies(q) == ("reliable", "transient_local") for q in (writer, reader))
    report.add("the e-stop is RELIABLE + TRANSIENT_LOCAL on both sides", latched,
               "writer {}/{}, reader {}/{}".format(*_policies(writer), *_policies(reader)),
               "Every e-stop message must arrive (reliable), and a node that starts after the e-stop "
               "was pressed must still learn it (transient_local, depth 1 keeps the current state).")
    full = _resolve(namespace, topic["name"])
    try:
        received = rt.wait_for_messages(full, EStop, count=1, timeout=timeout, qos=reader)
        ok, detail = True, f"it received engaged={received[0].engaged} at once"
    except WaitTimeout:
        ok, detail = False, f"nothing within {timeout:g} s"
    report.add("a late joiner with your e-stop QoS learns the current e-stop state", ok, detail,
               "The safety monitor published the e-stop state long ago; only a TRANSIENT_LOCAL "
               "reader (of a TRANSIENT_LOCAL writer) gets it when it joins now.")


def _check_data_flows(report, rt, namespace, topics) -> None:
    silent = []
    checked = 0
    for topic in topics:
        if topic["type"] not in SENSOR_TYPES:
            continue
        checked += 1
        full = _resolve(namespace, topic["name"])
        try:
            rt.wait_for_messages(full, topic["type"], count=1, timeout=4.0, qos=topic["subscriber_qos"])
        except (WaitTimeout, CourseError):
            silent.append(full)
    if checked:
        report.add("sensor data reaches a reader with your QoS", not silent,
                   f"nothing on {', '.join(silent)}" if silent else f"{checked} sensor topics",
                   "An incompatible reader gets nothing at all: compare your QoS with the "
                   "publisher's in %ros2 topic info -v.")


def _resolve(namespace: str, name: str) -> str:
    """A design's name (relative to ``namespace``, or absolute) -> its full name."""
    return name if name.startswith("/") else full_name(namespace, name)
