"""Chapter 07, DDS and discovery, measured on the live system.

* :mod:`.communication_models` - four communication models routed message by message (a count in pure Python,
  not a measurement: no DDS runs there);
* :mod:`.listener` - a child-process listener that reports what it hears (domains, discovery server);
  the spare domain and the domain probe come from :mod:`course_helpers.core.domains`;
* :mod:`.discovery` - how long a new process takes to find a node (the probe and the anchor);
* :mod:`.discovery_settings` - discovery with Fast DDS's default announcement period against the course's, and
  what announcing costs;
* :mod:`.server` - eProsima's discovery server, started and stopped from the notebook;
* :mod:`.server_failure` - chapter 01's failure experiment with a discovery server where ROS 1 had its master
  (:func:`side_by_side` prints it beside chapter 01's results);
* :mod:`.machines` - two network namespaces joined by a veth pair: the discovery range across a link;
* :mod:`.names` - ROS names as DDS topics and types, and what a GUID says;
* :mod:`.middleware` - the installed rmw implementations;
* :mod:`.transports` - one message bounced in one process, over shared memory and over UDP;
* :mod:`.security` - what rcl and Fast DDS do when a node asks for DDS security;
* :mod:`.cyclone` - another vendor, Eclipse Cyclone DDS, in the kernel's domain (notebook 07b);
* :mod:`.discovery_wire` - one node's SPDP and SEDP messages, captured and counted (notebook 07b).

The notebook uses ``from course_helpers.chapters import ch07_dds as dds`` and ``dds.<name>``.
"""

# ruff: noqa: F401  (every import below is a re-export for the notebook)

from course_helpers.chapters.ch07_dds.communication_models import (
    MODELS,
    ModelResult,
    center_failure_table,
    compare_models,
    plot_models,
    simulate_model,
)
from course_helpers.chapters.ch07_dds.cyclone import (
    close_cyclone,
    cyclone_config,
    cyclone_domain,
    cyclone_participants,
    cyclone_unavailable_reason,
)
from course_helpers.chapters.ch07_dds.discovery import (
    DiscoveryAnchor,
    DiscoveryProbe,
    DiscoveryTiming,
    discovery_probe,
    measure_discovery,
    summarize_discovery,
)
from course_helpers.chapters.ch07_dds.discovery_settings import (
    SETTINGS,
    AnnouncementTraffic,
    DiscoveryComparison,
    compare_discovery,
    discovery_port,
    listen_to_announcements,
    measure_announcements,
    plot_discovery,
)
from course_helpers.chapters.ch07_dds.discovery_wire import (
    DiscoveryCount,
    count_discovery,
    discovery_table,
    discovery_wire_unavailable_reason,
)
from course_helpers.chapters.ch07_dds.listener import ReportingListener, heard_lines
from course_helpers.chapters.ch07_dds.machines import LinkResult, link_table, two_machines
from course_helpers.chapters.ch07_dds.middleware import installed_rmw_implementations
from course_helpers.chapters.ch07_dds.names import (
    DdsEntity,
    dds_entities,
    guid_prefix,
    guid_process_id,
    guid_vendor,
    ros_name_from_dds,
    ros_type_from_dds,
)
from course_helpers.chapters.ch07_dds.security import (
    empty_keystore,
    secure_node_attempts,
    try_security_settings,
)
from course_helpers.chapters.ch07_dds.server import (
    DiscoveryServer,
    free_udp_port,
    start_discovery_server,
    stop_discovery_servers,
)
from course_helpers.chapters.ch07_dds.server_failure import server_failure_experiment
from course_helpers.chapters.ch07_dds.transports import (
    BOUNCE_QOS,
    TRANSPORT_LABELS,
    Ping,
    Pong,
    TransportResult,
    measure_transports,
    plot_transports,
    run_ping,
)
from course_helpers.core.domains import nodes_in_domain, reserve_spare_domain
from course_helpers.viz.failure_table import FailureResult, side_by_side
