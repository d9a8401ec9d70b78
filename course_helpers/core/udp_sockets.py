"""The UDP sockets a process holds, and which of them another machine could reach (chapters 00, 01).

Fast DDS opens UDP sockets for discovery and for data. Where they are bound says how far the
process can be reached: a socket bound to a loopback address (``127.0.0.1``, ``::1``) only
receives from this machine, and only sends to it; one bound to ``0.0.0.0`` or to a network
interface's address is open to the network. Reading the sockets tells what the middleware
really did, whatever the environment variables and configuration files say.
"""

from __future__ import annotations

import ipaddress
import os


def udp_sockets(pid: int | None = None) -> list[tuple[str, int]]:
    """The local ``(address, port)`` of every UDP socket of process ``pid`` (this one by default).

    Sorted by port, then address; an IPv6 address is given without brackets.
    """
    import psutil

    process = psutil.Process(os.getpid() if pid is None else pid)
    found = {(c.laddr.ip, c.laddr.port) for c in process.net_connections(kind="udp") if c.laddr}
    return sorted(found, key=lambda socket: (socket[1], socket[0]))


def is_loopback(address: str) -> bool:
    """True for an address only this machine can use (``127.0.0.0/8``, ``::1``)."""
    try:
        return ipaddress.ip_address(address.split("%", 1)[0]).is_loopback
    except ValueError:
        return False


def reachable_from_network(sockets: list[tuple[str, int]]) -> list[tuple[str, int]]:
    """The sockets of ``sockets`` that are not bound to a loopback address (``0.0.0.0`` included)."""
    return [socket for socket in sockets if not is_loopback(socket[0])]
