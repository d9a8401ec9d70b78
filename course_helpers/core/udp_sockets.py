"""The UDP sockets a process holds, what Fast DDS opened each for, and which of them another machine could
reach.

Fast DDS opens UDP sockets for discovery and for data. Where they are bound says how far the
process can be reached: a socket bound to a loopback address (``127.0.0.1``, ``::1``) only
receives from this machine, and only sends to it; one bound to ``0.0.0.0`` or to a network
interface's address is open to the network. Reading the sockets tells what the middleware
really did, whatever the environment variables and configuration files say.
"""

from __future__ import annotations

import ipaddress
import os
import socket


def udp_sockets() -> list[tuple[str, int]]:
    """The local ``(address, port)`` of every bound UDP socket of this process.

    Sorted by port, then address; an IPv6 address is given without brackets. Each socket is asked
    itself (``getsockname`` on a duplicate of its descriptor), so the answer is exact however many
    sockets other processes open and close meanwhile. A listing read from ``/proc/net/udp`` is not:
    the kernel writes that file in chunks, and when sockets before the reading point close between two
    chunks, the next chunk starts further on and skips entries.
    """
    found = set()
    for name in os.listdir("/proc/self/fd"):
        try:
            if not os.readlink(f"/proc/self/fd/{name}").startswith("socket:"):
                continue
            duplicate = os.dup(int(name))
        except OSError:  # closed meanwhile, by another thread (the listing's own descriptor too)
            continue
        try:
            sock = socket.socket(fileno=duplicate)  # owns the duplicate from here on
        except OSError:
            os.close(duplicate)
            continue
        with sock:  # closes the duplicate only
            if sock.type == socket.SOCK_DGRAM and sock.family in (socket.AF_INET, socket.AF_INET6):
                address, port = sock.getsockname()[:2]
                if port:  # bound
                    found.add((address, port))
    return sorted(found, key=lambda entry: (entry[1], entry[0]))


def is_loopback(address: str) -> bool:
    """True for an address only this machine can use (``127.0.0.0/8``, ``::1``)."""
    try:
        return ipaddress.ip_address(address.split("%", 1)[0]).is_loopback
    except ValueError:
        return False


def reachable_from_network(sockets: list[tuple[str, int]]) -> list[tuple[str, int]]:
    """The sockets of ``sockets`` that are not bound to a loopback address (``0.0.0.0`` included)."""
    return [socket for socket in sockets if not is_loopback(socket[0])]


# rmw_fastrtps asks for a listening port of their own ("unique network flow") for the subscription
# that hears the graph's updates, ros_discovery_info (init_rmw_context_impl.cpp), and Fast DDS picks the
# first free one from its port base minus 400 up to the base (RTPSParticipantImpl.cpp), in any domain.
# So each participant that rmw_fastrtps creates holds one UDP port in this range.
GRAPH_PORTS = (7400 - 400, 7400)
RTPS_PORTS = (7400, 32768)  # the ports of RTPS domains (7400 + 250 per domain), below the OS's own


def discovery_port(domain: int, participant_id: int) -> int:
    """The unicast discovery (metatraffic) port of participant ``participant_id`` in ``domain``, by the
    RTPS port mapping (the specification's defaults, which Fast DDS uses); its data port is the next one."""
    return 7400 + 250 * domain + 10 + 2 * participant_id


def classify_port(port: int, domain_id: int) -> str:
    """What a UDP ``port`` of a participant in ``domain_id`` is for, as a short phrase.

    Follows the RTPS port mapping (base 7400 + 250 x domain), e.g. 'discovery, unicast
    (participant 0)'.
    """
    base = 7400 + 250 * domain_id
    if port == base:
        return "discovery, multicast"
    if port == base + 1:
        return "user data, multicast"
    offset = port - base - 10
    if 0 <= offset < 240:
        participant = offset // 2
        kind = "discovery" if offset % 2 == 0 else "user data"
        return f"{kind}, unicast (participant {participant})"
    if port >= 32768:
        return "sending socket (ephemeral port picked by the OS)"
    if is_graph_port(port):
        return "graph updates (ros_discovery_info), a port of their own"
    return "another Fast DDS port, outside the domain's RTPS range"


def is_graph_port(port: int) -> bool:
    """True for a port in :data:`GRAPH_PORTS`: a participant's ``ros_discovery_info`` reader listens there."""
    return GRAPH_PORTS[0] <= port < GRAPH_PORTS[1]
