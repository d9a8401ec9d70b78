"""ROS names as the DDS topics and types they become (the ``rt/``, ``rq/``, ``rr/`` prefixes),
and what an endpoint's GUID says about the participant and process behind it.
"""

from __future__ import annotations

from dataclasses import dataclass

from course_helpers.core.dds_vendors import gid_prefix, gid_vendor
from course_helpers.core.names import is_hidden

PREFIXES = {
    "rt": "topic",
    "rq": "service request",
    "rr": "service reply",
    "rs": "service (unused by Fast DDS)",
    "rp": "parameter (reserved)",
    "ra": "action (reserved)",
}


@dataclass
class DdsEntity:
    """One DDS topic in the graph and the ROS name it comes from."""

    dds_topic: str
    dds_type: str
    prefix: str
    meaning: str
    ros_name: str
    ros_type: str


def ros_type_from_dds(dds_type: str) -> str:
    """'std_msgs::msg::dds_::String_' -> 'std_msgs/msg/String' (services: Request_/Response_ dropped)."""
    parts = dds_type.split("::")
    if len(parts) == 4 and parts[2] == "dds_" and parts[3].endswith("_"):
        name = parts[3][:-1]
        for suffix in ("_Request", "_Response"):
            if name.endswith(suffix):
                name = name[: -len(suffix)]
        return f"{parts[0]}/{parts[1]}/{name}"
    return dds_type


def ros_name_from_dds(dds_topic: str) -> tuple[str, str, str]:
    """``'rq/resetRequest'`` -> ``('rq', 'service request', '/reset')``; an unprefixed name is the
    middleware's own topic and comes back as ``('', meaning, name)``."""
    head, _, rest = dds_topic.partition("/")
    if head in PREFIXES and rest:
        name = "/" + rest
        if head == "rq" and name.endswith("Request"):
            name = name[: -len("Request")]
        elif head == "rr" and name.endswith("Reply"):
            name = name[: -len("Reply")]
        return head, PREFIXES[head], name
    return "", "the middleware's own topic, not a ROS name", dds_topic


def dds_entities(rt, contains: str = "", include_hidden: bool = False) -> list[DdsEntity]:
    """The DDS topics in ``rt``'s domain (raw, un-demangled names), each with the ROS name it carries.

    ``contains`` keeps only DDS names containing that text; hidden ROS names (a token starting
    with '_', such as the course runtime's own services) are left out unless ``include_hidden``.
    Returns :class:`DdsEntity` rows sorted by DDS topic and type.
    """
    rows = []
    for dds_topic, types in rt.graph.get_topic_names_and_types(no_demangle=True):
        if contains and contains not in dds_topic:
            continue
        prefix, meaning, ros_name = ros_name_from_dds(dds_topic)
        if not include_hidden and is_hidden(ros_name):
            continue
        for dds_type in types:
            rows.append(DdsEntity(dds_topic, dds_type, prefix, meaning, ros_name,
                                  ros_type_from_dds(dds_type)))
    return sorted(rows, key=lambda r: (r.dds_topic, r.dds_type))


def guid_prefix(gid) -> str:
    """The participant part (first 12 bytes) of an endpoint GUID (bytes or a list of ints), as dotted hex."""
    return gid_prefix(gid)


def guid_process_id(gid) -> int:
    """The (low 16 bits of the) process ID that Fast DDS writes into bytes 4-5 of a GUID prefix."""
    raw = bytes(gid)
    return raw[4] | (raw[5] << 8)


def guid_vendor(gid) -> str:
    """The DDS vendor in the first two bytes of a GUID (01.0f is eProsima, 01.10 Eclipse Cyclone DDS)."""
    return gid_vendor(gid)
