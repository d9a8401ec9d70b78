"""``%ros2 service list|type|info|find|call`` (chapter 04).
"""

from __future__ import annotations

from course_helpers.core.errors import CourseError, WaitTimeout
from course_helpers.core.msg_yaml import (
    set_message_fields,
    values_from_yaml,
)
from course_helpers.core.validation import interface_name, resolve_interface
from course_helpers.notebook.ros2cli._common import (
    SERVICE_WAIT_S,
    Verb,
    _check_same_type,
    _is_hidden,
    _positive_float,
    _topic_arg,
    add_verb_table,
    count_of,
    name_of,
    option,
    print_names,
    print_types,
    show_types,
)


def _service_types(rt, service: str) -> list[str]:
    for name, types in rt.graph.get_service_names_and_types():
        if name == service:
            return list(types)
    return []


def _service_list(rt, args):
    pairs = sorted((n, t) for n, t in rt.graph.get_service_names_and_types()
                   if args.include_hidden_services or not _is_hidden(n))
    print_names(pairs, args.show_types, args.count_services)
    return None


def _service_type(rt, args):
    return print_types("service", args.service_name, _service_types(rt, _topic_arg(args.service_name)))


def _service_info(rt, args):
    service = _topic_arg(args.service_name)
    types = _service_types(rt, service)
    if not types:
        return print_types("service", args.service_name, types)
    print(f"Type: {', '.join(types)}")
    print(f"Clients count: {rt.graph.count_clients(service)}")
    print(f"Services count: {rt.graph.count_services(service)}")
    return None


def _service_find(rt, args):
    wanted = interface_name(_service_class(args.service_type))
    for name in sorted(n for n, types in rt.graph.get_service_names_and_types()
                       if wanted in types and not _is_hidden(n)):
        print(name)
    return None


def _service_class(type_name: str):
    cls = resolve_interface(type_name, "srv")
    if not hasattr(cls, "Request") or hasattr(cls, "Goal"):
        raise CourseError(f"{type_name!r} is not a service type; services use types such as "
                          "std_srvs/srv/SetBool or std_srvs/srv/Trigger")
    return cls


def _service_call(rt, args):
    service = _topic_arg(args.service_name)
    srv_class = _service_class(args.service_type)
    _check_same_type("service", service, srv_class, _service_types(rt, service))
    request = set_message_fields(srv_class.Request(), values_from_yaml(args.values, "request"),
                                 now=lambda: rt.graph.get_clock().now().to_msg())
    client = rt.graph.create_client(srv_class, service)
    try:
        if not client.service_is_ready():
            print("waiting for service to become available...")
            try:
                rt.wait_until(client.service_is_ready, args.timeout, f"service {service}")
            except WaitTimeout:
                return (f"Service {service} ({interface_name(srv_class)}) did not become available within "
                        f"{args.timeout:g} s; check %ros2 service list -t")
        print(f"requester: making request: {request!r}\n")
        response = rt.wait_for_future(client.call_async(request), args.timeout, f"the response of {service}")
        print(f"response:\n{response!r}\n")
    finally:
        rt.call_in_executor(rt.graph.destroy_client, client)
    return None


SERVICE_NAME = name_of("service", "service_name", "/add_two_ints")
VERBS = (
    Verb("list", "Output a list of available services", _service_list, (
        show_types("service"), count_of("services"),
        option("--include-hidden-services", action="store_true", help="Consider hidden services as well"))),
    Verb("type", "Output a service's type", _service_type, (SERVICE_NAME,)),
    Verb("info", "Print a service's type and how many servers and clients it has", _service_info,
         (SERVICE_NAME,)),
    Verb("find", "Output a list of available services of a given type", _service_find, (
        option("service_type", help="Name of the ROS service type, e.g. std_srvs/srv/SetBool"),)),
    Verb("call", "Call a service", _service_call, (
        name_of("service", "service_name", "/add_two_ints", " to call"),
        option("service_type", help="Type of the ROS service, e.g. std_srvs/srv/SetBool"),
        option("values", nargs="?", default="{}", help="Request values in YAML, e.g. \"{data: true}\""),
        option("--timeout", type=_positive_float, default=SERVICE_WAIT_S, metavar="S",
               help=f"Wait at most S seconds for the server and for the response "
                    f"(default: {SERVICE_WAIT_S:g})"))),
)


def add_verbs(parser):
    add_verb_table(parser, VERBS)
