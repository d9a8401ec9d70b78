"""``%ros2 param list|get|set|dump|describe`` over the parameter services (chapter 06).
"""

from __future__ import annotations

import yaml

from course_helpers.core.errors import WaitTimeout
from course_helpers.notebook.ros2cli._common import (
    INCLUDE_HIDDEN_NODES,
    NODE_NAME,
    SERVICE_WAIT_S,
    Verb,
    _absolute,
    _graph_node_names,
    add_verb_table,
    option,
)


def _require_node(rt, node_name: str, include_hidden: bool) -> str | None:
    """The absolute node name if the node is in the graph (waiting up to 1 s, as ros2cli does)."""
    fqn = _absolute(node_name)
    try:
        rt.wait_until(lambda: fqn in _graph_node_names(rt, include_hidden), 1.0, f"node {fqn}")
    except WaitTimeout:
        return None
    return fqn


_PARAM_TYPES = {0: "not set", 1: "boolean", 2: "integer", 3: "double", 4: "string", 5: "byte array",
                6: "boolean array", 7: "integer array", 8: "double array", 9: "string array"}


_PARAM_LABELS = {1: "Boolean value is:", 2: "Integer value is:", 3: "Double value is:",
                 4: "String value is:", 5: "Byte values are:", 6: "Boolean values are:",
                 7: "Integer values are:", 8: "Double values are:", 9: "String values are:"}


def _call_service(rt, srv_class, service: str, request, timeout: float = SERVICE_WAIT_S):
    """Call a service from the runtime's hidden node and return the response (WaitTimeout if none)."""
    client = rt.graph.create_client(srv_class, service)
    try:
        rt.wait_until(client.service_is_ready, timeout, f"service {service}")
        return rt.wait_for_future(client.call_async(request), timeout, f"the response of {service}")
    finally:
        rt.call_in_executor(rt.graph.destroy_client, client)


def _parameter_nodes(rt, node_name: str | None, include_hidden: bool) -> list[str] | str:
    if node_name:
        fqn = _require_node(rt, node_name, include_hidden)
        return [fqn] if fqn else "Node not found"
    services = {name for name, _ in rt.graph.get_service_names_and_types()}
    return sorted({fqn for fqn in _graph_node_names(rt, include_hidden)
                   if f"{fqn.rstrip('/')}/list_parameters" in services})


def _list_parameter_names(rt, fqn: str, prefixes=()) -> list[str]:
    from rcl_interfaces.srv import ListParameters

    request = ListParameters.Request(prefixes=list(prefixes))
    return sorted(_call_service(rt, ListParameters, f"{fqn}/list_parameters", request).result.names)


def _get_parameter_values(rt, fqn: str, names: list[str]) -> list:
    from rcl_interfaces.srv import GetParameters

    return list(_call_service(rt, GetParameters, f"{fqn}/get_parameters",
                              GetParameters.Request(names=names)).values)


def _describe_parameters(rt, fqn: str, names: list[str]) -> list:
    from rcl_interfaces.srv import DescribeParameters

    return list(_call_service(rt, DescribeParameters, f"{fqn}/describe_parameters",
                              DescribeParameters.Request(names=names)).descriptors)


def _param_list(rt, args):
    nodes = _parameter_nodes(rt, args.node_name, args.include_hidden_nodes)
    if isinstance(nodes, str):
        return nodes
    for fqn in nodes:
        try:
            names = _list_parameter_names(rt, fqn, args.param_prefixes)
        except WaitTimeout as exc:
            print(f"Exception while calling service of node '{fqn}': {exc}")
            continue
        if not args.node_name:
            print(f"{fqn}:")
        types = {}
        if args.param_type and names:
            types = {d.name: _PARAM_TYPES.get(d.type, "unknown")
                     for d in _describe_parameters(rt, fqn, names)}
        for name in names:
            print(f"  {name} (type: {types.get(name, 'unknown')})" if args.param_type else f"  {name}")
    return None


def _python_value(parameter_value):
    from rclpy.parameter import parameter_value_to_python

    value = parameter_value_to_python(parameter_value)
    if isinstance(value, list):
        value = [v[0] if isinstance(v, bytes) and len(v) == 1 else v for v in value]
    return value


def _param_get(rt, args):
    fqn = _require_node(rt, args.node_name, args.include_hidden_nodes)
    if fqn is None:
        return "Node not found"
    values = _get_parameter_values(rt, fqn, [args.parameter_name])
    if not values:
        return "Parameter not set"
    value = values[0]
    if value.type == 0:
        print("Parameter not set.")
        return None
    python = _python_value(value)
    if args.hide_type:
        print(python)
    else:
        print(_PARAM_LABELS.get(value.type, "Value is:"), python)
    return None


def _param_set(rt, args):
    from rcl_interfaces.msg import Parameter
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import get_parameter_value

    fqn = _require_node(rt, args.node_name, args.include_hidden_nodes)
    if fqn is None:
        return "Node not found"
    parameter = Parameter(name=args.parameter_name, value=get_parameter_value(args.value))
    response = _call_service(rt, SetParameters, f"{fqn}/set_parameters",
                             SetParameters.Request(parameters=[parameter]))
    result = response.results[0]
    if result.successful:
        print("Set parameter successful" + (f": {result.reason}" if result.reason else ""))
    else:
        print("Setting parameter failed" + (f": {result.reason}" if result.reason else ""))
    return None


def _param_dump(rt, args):
    fqn = _require_node(rt, args.node_name, args.include_hidden_nodes)
    if fqn is None:
        return "Node not found"
    names = _list_parameter_names(rt, fqn)
    values = _get_parameter_values(rt, fqn, names) if names else []
    tree: dict = {}
    for name, value in zip(names, values, strict=False):
        branch = tree
        *parents, leaf = name.split(".")
        for part in parents:
            branch = branch.setdefault(part, {})
        branch[leaf] = _python_value(value)
    print(yaml.safe_dump({fqn: {"ros__parameters": tree}}, default_flow_style=False))
    return None


def _param_describe(rt, args):
    fqn = _require_node(rt, args.node_name, args.include_hidden_nodes)
    if fqn is None:
        return "Node not found"
    descriptors = _describe_parameters(rt, fqn, list(args.parameter_names))
    if not descriptors:
        return "Parameter not found"
    for d in descriptors:
        print(f"Parameter name: {d.name}")
        print(f"  Type: {_PARAM_TYPES.get(d.type, 'unknown')}")
        if d.description:
            print(f"  Description: {d.description}")
        if d.additional_constraints or d.read_only or d.dynamic_typing or d.integer_range or \
                d.floating_point_range:
            print("  Constraints:")
            if d.read_only:
                print("    Read only: true")
            if d.dynamic_typing:
                print("    Dynamic typing: true")
            for each in list(d.integer_range) + list(d.floating_point_range):
                print(f"    Min value: {each.from_value}")
                print(f"    Max value: {each.to_value}")
                if each.step:
                    print(f"    Step: {each.step}")
            if d.additional_constraints:
                print(f"    Additional constraints: {d.additional_constraints}")
    return None


PARAMETER_NAME = option("parameter_name", help="Name of the parameter")
VERBS = (
    Verb("list", "Output a list of available parameters", _param_list, (
        option("node_name", nargs="?", help="Name of the ROS node (default: every node)"),
        option("--param-type", action="store_true", help="Print parameter types with parameter names"),
        option("--param-prefixes", nargs="+", default=[], metavar="PREFIX",
               help="Only list parameters with the provided prefixes"),
        INCLUDE_HIDDEN_NODES)),
    Verb("get", "Get a parameter", _param_get, (
        NODE_NAME, PARAMETER_NAME,
        option("--hide-type", action="store_true", help="Hide the type information"), INCLUDE_HIDDEN_NODES)),
    Verb("set", "Set a parameter", _param_set, (
        NODE_NAME, PARAMETER_NAME,
        option("value", help="Value of the parameter (YAML: 5, 2.5, true, hello, [1, 2])"),
        INCLUDE_HIDDEN_NODES)),
    Verb("dump", "Show all of the parameters of a node in YAML file format", _param_dump,
         (NODE_NAME, INCLUDE_HIDDEN_NODES)),
    Verb("describe", "Show descriptive information about declared parameters", _param_describe, (
        NODE_NAME, option("parameter_names", nargs="+", help="Names of the parameters"),
        INCLUDE_HIDDEN_NODES)),
)


def add_verbs(parser):
    add_verb_table(parser, VERBS)
