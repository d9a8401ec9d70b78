"""Which UDP sockets this process holds: read exactly, whatever other processes do meanwhile.

``course_helpers.core.udp_sockets.udp_sockets`` answers chapter 01's "which ports did the participant
open" and the participant tests' before-and-after footprints. It asks each socket itself. A listing
read from ``/proc/net/udp`` (psutil's) skips entries while other processes open and close sockets: in
a trial beside two such processes, 98 of 100 of its reads missed some of 300 sockets held here, and
the logic stage once failed on a footprint that had lost a participant's two ports that way.
"""

from __future__ import annotations

import socket
import subprocess
import sys

from course_helpers.core.udp_sockets import udp_sockets

# a process that keeps opening and closing 50 UDP sockets, until it is killed
CHURN = """
import socket
while True:
    sockets = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(50)]
    for sock in sockets:
        sock.bind(("127.0.0.1", 0))
    for sock in sockets:
        sock.close()
"""


def _bound(family: int, kind: int, address: str) -> socket.socket:
    sock = socket.socket(family, kind)
    sock.bind((address, 0))
    return sock


def test_bound_udp_sockets_are_listed_and_nothing_else():
    udp4 = _bound(socket.AF_INET, socket.SOCK_DGRAM, "127.0.0.1")
    udp6 = _bound(socket.AF_INET6, socket.SOCK_DGRAM, "::1")
    tcp = _bound(socket.AF_INET, socket.SOCK_STREAM, "127.0.0.1")
    unbound = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    with udp4, udp6, tcp, unbound:
        listed = udp_sockets()
        assert ("127.0.0.1", udp4.getsockname()[1]) in listed
        assert ("::1", udp6.getsockname()[1]) in listed
        assert tcp.getsockname()[1] not in [port for _address, port in listed]
        assert all(port for _address, port in listed)  # an unbound socket has no port to list


def test_every_read_lists_every_socket_while_other_processes_open_and_close_theirs():
    churners = [subprocess.Popen([sys.executable, "-c", CHURN]) for _ in range(2)]
    held = [_bound(socket.AF_INET, socket.SOCK_DGRAM, "127.0.0.1") for _ in range(300)]
    try:
        expected = {sock.getsockname()[1] for sock in held}
        short = [expected - {port for _address, port in udp_sockets()} for _ in range(100)]
        missed = [gone for gone in short if gone]
        assert not missed, f"{len(missed)} of 100 reads missed sockets, e.g. {max(missed, key=len)}"
    finally:
        for churner in churners:
            churner.kill()
            churner.wait()
        for sock in held:
            sock.close()
