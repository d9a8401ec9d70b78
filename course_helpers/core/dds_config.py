"""How the course's participants are configured for Fast DDS: discovery timing and transports.

**Fast discovery.** When a participant starts, it announces itself at once and the participants
already running answer at once; the answer reaches the newcomer's socket within about a
millisecond (seen with strace), but often arrives too early to be used inside Fast DDS, so the
newcomer learns of each older participant only at that one's next periodic announcement, every
3 s by default: a node in a new process was seen after anything from 0 to 3 s. The course's
participants (the kernel and its children) announce themselves every ``ANNOUNCEMENT_S`` instead,
through a Fast DDS XML profile named by ``FASTRTPS_DEFAULT_PROFILES_FILE`` (the variable Fast DDS
2.14 reads). With localhost-only discovery an announcement goes to the ports of 32 possible
participants: about 31 datagrams of 500 B, 16 kB of UDP payload (measured in chapter 07), so
about 155 kB/s per participant at 0.1 s against about 5 kB/s at the default 3 s.

**UDP only.** ``udp_loopback_env(directory)`` is the environment for a child whose samples must
cross the loopback network instead of shared memory (chapter 07's transports, the QoS lab's UDP
mode). rmw_fastrtps replaces the transports of a participant whose discovery range is LOCALHOST,
so such a child uses the SUBNET range with 127.0.0.1 as its only static peer, and a profile whose
one transport is UDPv4 on 127.0.0.1 (with the same discovery timing).

A user who set ``FASTRTPS_DEFAULT_PROFILES_FILE`` keeps their own profile.
"""

from __future__ import annotations

import os

PROFILE_ENV = "FASTRTPS_DEFAULT_PROFILES_FILE"
ANNOUNCEMENT_S = 0.1  # s; the course's periodic participant announcement (Fast DDS default: 3 s)
DEFAULT_ANNOUNCEMENT_S = 3.0  # s; what participants outside the course use
LEASE_S = 20  # s; how long a silent participant is kept (Fast DDS's default)

_HEAD = ('<?xml version="1.0" encoding="UTF-8" ?>\n'
         '<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">\n')
_UDP_TRANSPORT = """  <transport_descriptors>
    <transport_descriptor>
      <transport_id>course_udp_loopback</transport_id>
      <type>UDPv4</type>
      <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>
    </transport_descriptor>
  </transport_descriptors>
"""


def profile_xml(announcement_s: float = ANNOUNCEMENT_S, udp_only: bool = False) -> str:
    """A Fast DDS default participant profile: the announcement period, and optionally UDP only."""
    seconds = int(announcement_s)
    nanoseconds = round((announcement_s - seconds) * 1e9)
    transports = ("      <userTransports><transport_id>course_udp_loopback</transport_id></userTransports>\n"
                  "      <useBuiltinTransports>false</useBuiltinTransports>\n") if udp_only else ""
    return (_HEAD + (_UDP_TRANSPORT if udp_only else "")
            + '  <participant profile_name="course_participant" is_default_profile="true">\n'
            + "    <rtps>\n"
            + transports
            + "      <builtin>\n        <discovery_config>\n"
            + f"          <leaseDuration><sec>{LEASE_S}</sec><nanosec>0</nanosec></leaseDuration>\n"
            + f"          <leaseAnnouncement><sec>{seconds}</sec><nanosec>{nanoseconds}</nanosec>"
            + "</leaseAnnouncement>\n"
            + "        </discovery_config>\n      </builtin>\n"
            + "    </rtps>\n  </participant>\n</profiles>\n")


def write_profile(directory: str, name: str, text: str) -> str:
    """Write a profile into ``directory`` (once per content) and return its path."""
    path = os.path.join(directory, name)
    try:
        with open(path, encoding="utf-8") as handle:
            if handle.read() == text:
                return path
    except OSError:
        pass
    with open(path, "w", encoding="utf-8") as handle:
        handle.write(text)
    return path


def apply_course_discovery(directory: str) -> str:
    """Make this process and its children announce themselves every ``ANNOUNCEMENT_S``.

    Sets ``FASTRTPS_DEFAULT_PROFILES_FILE`` in ``os.environ`` (before the first participant is
    created) unless it is set already: by the user, or by the kernel for this child. Returns the
    profile in use.
    """
    if not os.environ.get(PROFILE_ENV):
        os.environ[PROFILE_ENV] = write_profile(directory, "course_fast_discovery.xml", profile_xml())
    return os.environ[PROFILE_ENV]


def default_discovery_env(directory: str) -> dict[str, str]:
    """Environment for a child that uses Fast DDS's default announcement period (3 s), for comparison."""
    path = write_profile(directory, "fastdds_default_discovery.xml", profile_xml(DEFAULT_ANNOUNCEMENT_S))
    return {PROFILE_ENV: path}


def udp_loopback_env(directory: str) -> dict[str, str]:
    """Environment variables that make a child's participant use UDP on 127.0.0.1 only.

    Writes the XML profile into ``directory`` and returns the variables to pass as ``env=`` to
    ``rt.spawn``.
    """
    path = write_profile(directory, "course_udp_loopback.xml", profile_xml(udp_only=True))
    return {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": "127.0.0.1",
            PROFILE_ENV: path}
