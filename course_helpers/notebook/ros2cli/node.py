"""``%ros2 node list|info`` (chapters 01, 02 and 10).
"""

from __future__ import annotations

from course_helpers.notebook.ros2cli._common import (
    Verb,
    _absolute,
    _graph_node_names,
    _is_hidden,
    add_verb_table,
    count_of,
    option,
)


def _split_node_name(fqn: str) -> tuple[str, str]:
    """'/ns/name' -> ('/ns', 'name'); '/name' -> ('/', 'name')."""
    namespace, _, name = _absolute(fqn).rpartition("/")
    return namespace or "/", name


def _print_names_and_types(pairs) -> None:
    # ros2cli prints one (possibly empty) line per section: print(*lines, sep='\n')
    print(*[f"    {name}: {', '.join(types)}" for name, types in pairs], sep="\n")


def _node_list(rt, args):
    names = _graph_node_names(rt, args.all)
    if args.count_nodes:
        print(len(names))
        return None
    if len(set(names)) < len(names):
        print("WARNING: Be aware that there are nodes in the graph that share an exact name, which can "
              "have unintended side effects.")
    for name in names:
        print(name)
    return None


def _node_info(rt, args):
    fqn = _absolute(args.node_name)
    names = _graph_node_names(rt, include_hidden=True)
    if fqn not in names:
        return f"Unable to find node '{args.node_name}'"
    if names.count(fqn) > 1:
        print(f'There are {names.count(fqn)} nodes in the graph with the exact name "{fqn}". '
              "You are seeing information about only one of them.")
    from rclpy.action import graph as action_graph

    namespace, name = _split_node_name(fqn)
    graph = rt.graph
    keep = (lambda pairs: sorted(pairs)) if args.include_hidden else (
        lambda pairs: sorted((n, t) for n, t in pairs if not _is_hidden(n)))
    try:
        sections = [
            ("Subscribers", graph.get_subscriber_names_and_types_by_node(name, namespace)),
            ("Publishers", graph.get_publisher_names_and_types_by_node(name, namespace)),
            ("Service Servers", graph.get_service_names_and_types_by_node(name, namespace)),
            ("Service Clients", graph.get_client_names_and_types_by_node(name, namespace)),
            ("Action Servers",
             action_graph.get_action_server_names_and_types_by_node(graph, name, namespace)),
            ("Action Clients",
             action_graph.get_action_client_names_and_types_by_node(graph, name, namespace)),
        ]
    except Exception:  # the node left the graph meanwhile
        return f"Unable to find node '{args.node_name}'"
    print(fqn)
    for title, pairs in sections:
        print(f"  {title}:")
        _print_names_and_types(keep(pairs))
    return None


VERBS = (
    Verb("list", "Output a list of available nodes", _node_list, (
        option("-a", "--all", action="store_true", help="Display all nodes even hidden ones"),
        count_of("nodes"))),
    Verb("info", "Output information about a node", _node_info, (
        option("node_name", help="Fully qualified node name, e.g. /talker"),
        option("--include-hidden", action="store_true",
               help="Display hidden topics, services, and actions as well"))),
)


def add_verbs(parser):
    add_verb_table(parser, VERBS)
