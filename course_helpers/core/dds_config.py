"""How the course's participants are configured for Fast DDS: transports and discovery.

``udp_loopback_env(directory)`` is the environment for a child process whose samples must
cross the loopback network instead of shared memory (chapter 07's transport comparison,
the QoS lab's UDP mode). rmw_fastrtps replaces the transports of a participant whose
discovery range is LOCALHOST (so ``FASTDDS_BUILTIN_TRANSPORTS`` alone is ignored); such a
child therefore uses the SUBNET range with 127.0.0.1 as its only static peer, and a Fast DDS
XML profile whose one transport is UDPv4 limited to 127.0.0.1.
"""

from __future__ import annotations

import os

UDP_PROFILE_NAME = "course_udp_loopback.xml"
_UDP_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<!-- The participant gets one transport: UDPv4 on 127.0.0.1 (no shared memory) -->
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>
    <transport_descriptor>
      <transport_id>course_udp_loopback</transport_id>
      <type>UDPv4</type>
      <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>
    </transport_descriptor>
  </transport_descriptors>
  <participant profile_name="course_udp_only" is_default_profile="true">
    <rtps>
      <userTransports><transport_id>course_udp_loopback</transport_id></userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>
    </rtps>
  </participant>
</profiles>
"""


def udp_loopback_env(directory: str) -> dict[str, str]:
    """Environment variables that make a child's participant use UDP on 127.0.0.1 only.

    Writes the XML profile into ``directory`` (once) and returns the variables to pass as
    ``env=`` to ``rt.spawn``.
    """
    path = os.path.join(directory, UDP_PROFILE_NAME)
    if not os.path.exists(path):
        with open(path, "w", encoding="utf-8") as handle:
            handle.write(_UDP_PROFILE)
    return {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": "127.0.0.1",
            "FASTRTPS_DEFAULT_PROFILES_FILE": path}
