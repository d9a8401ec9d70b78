"""eProsima's discovery server (``fast-discovery-server``), started and stopped from the notebook.

The server runs through the course's process layer (group ``'server'``): it dies with the
kernel, a re-run stops the old one first, and the layer reaps it at exit.
"""

from __future__ import annotations

import os
import random
import signal
import socket
import sys
from dataclasses import dataclass

from course_helpers.core import dds_config, processes
from course_helpers.core.errors import CourseError
from course_helpers.core.udp_sockets import GRAPH_PORTS
from course_helpers.core.waiting import poll_until

SERVER_BINARY = "fast-discovery-server"
SERVER_LABEL = "discovery_server"
SERVER_GROUP = "server"
READY_TEXT = "Server is running"  # what the server prints once its participant is up


# Ports no socket gets unless it asks for that very port: below the ports Fast DDS picks by itself (a
# participant's graph port, then the RTPS domains' ports: core/udp_sockets.py) and the OS's ephemeral
# ports (given to every socket bound to port 0, as each Fast DDS sending socket is). A server restarted
# on its old port (chapter 07's server_failure_experiment) finds it free. A fresh-clone CI run's image
# stage saw a restart on an ephemeral port fail ("wasn't able to allocate the specified listening
# port") after the clients around it had opened sockets for two leases.
SERVER_PORTS = range(GRAPH_PORTS[0] - 1000, GRAPH_PORTS[0])
LINUX_EPHEMERAL_PORTS = range(32768, 61000)  # ip_local_port_range's default, if /proc does not say


def ephemeral_ports() -> range:
    """The ports the OS hands to sockets bound to port 0 (``net.ipv4.ip_local_port_range``)."""
    try:
        with open("/proc/sys/net/ipv4/ip_local_port_range", encoding="ascii") as handle:
            low, high = (int(part) for part in handle.read().split())
    except (OSError, ValueError):
        return LINUX_EPHEMERAL_PORTS
    return range(low, high + 1)


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that nothing is bound to right now, from :data:`SERVER_PORTS` (no socket
    takes one of those by chance), tried in random order (two kernels of one host seldom pick alike)."""
    ephemeral = ephemeral_ports()
    candidates = [port for port in SERVER_PORTS if port not in ephemeral]
    random.shuffle(candidates)
    for port in candidates:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    raise CourseError(f"no UDP port in {SERVER_PORTS.start}..{SERVER_PORTS.stop - 1} outside the OS's "
                      f"ephemeral ports ({ephemeral.start}..{ephemeral.stop - 1}) is free: pass port= "
                      f"(1024..65535) to start_discovery_server")


def udp_port_bound(port: int) -> bool:
    """True if some socket on this machine is bound to UDP ``port`` (asked with psutil, not probed)."""
    import psutil

    return any(c.laddr and c.laddr.port == port for c in psutil.net_connections(kind="udp"))


def _server_binary() -> str:
    path = os.path.join(os.path.dirname(sys.executable), SERVER_BINARY)
    if not os.path.exists(path):
        raise CourseError(f"{path} is missing: the Fast DDS wheel ships it; run `make lab` again")
    return path


@dataclass
class DiscoveryServer:
    """A ``fast-discovery-server`` process (a ``ChildProcess``) listening on 127.0.0.1:``port``.

    ``lease_s``: the lease it announces; its clients drop it that long after its last announcement.
    ``profile``: the path of the Fast DDS profile it read (``-x``).
    """

    port: int
    child: processes.ChildProcess
    lease_s: float = dds_config.LEASE_S
    profile: str = ""

    @property
    def alive(self) -> bool:
        """True while the server process runs."""
        return self.child.alive

    @property
    def pid(self) -> int:
        """The server program's process ID (its parent is the course's supervisor, ``core/supervisor.py``)."""
        return self.child.pid

    @property
    def returncode(self) -> int | None:
        """Its exit code, or None while it runs."""
        return self.child.returncode

    @property
    def address(self) -> str:
        """'127.0.0.1:<port>', the value clients put in ROS_DISCOVERY_SERVER."""
        return f"127.0.0.1:{self.port}"

    def client_env(self) -> dict:
        """Environment that makes a process a client of this server (server ID 0)."""
        return {"ROS_DISCOVERY_SERVER": self.address}

    def command(self) -> str:
        """Its command line as typed in a terminal: the program's name, then its options."""
        program, *options = self.child.argv[len(processes.PROGRAM_ARGV):]
        return " ".join([os.path.basename(program), *options])

    def profile_text(self) -> str:
        """The Fast DDS profile it read (``-x``): what makes it a SERVER, and the lease it announces."""
        with open(self.profile, encoding="utf-8") as handle:
            return handle.read()

    def ready(self) -> bool:
        """True once its UDP port is bound and it has said that it runs."""
        return udp_port_bound(self.port) and READY_TEXT in self.child.log()

    def output(self) -> str:
        """What the server printed (still there after it stopped)."""
        return self.child.log()

    def stop(self) -> int | None:
        """Stop the server (SIGTERM, then SIGKILL) and reap it; its exit code."""
        return processes.stop([self.child.label], group=SERVER_GROUP).get(self.child.label,
                                                                         self.child.returncode)

    def __repr__(self) -> str:
        state = "running" if self.alive else f"exited {self.returncode}"
        return f"<DiscoveryServer {self.address} {state}>"


def start_discovery_server(port: int | None = None, timeout: float = 5.0,
                           lease_s: float = dds_config.LEASE_S) -> DiscoveryServer:
    """Start eProsima's discovery server on 127.0.0.1; a server this kernel started earlier stops first.

    Args:
        port: the UDP port, 1024..65535 (a free one if None).
        timeout: seconds to wait until it listens.
        lease_s: the lease the server announces (Fast DDS's default, 20 s, unless given), 0.5..60 s:
            its clients drop a crashed server that long after its last announcement. The server
            reads it from a profile given with ``-x``.

    Returns the running :class:`DiscoveryServer`. Raises ``CourseError`` with its output if it
    ends or does not listen within ``timeout``.
    """
    port = free_udp_port() if port is None else int(port)
    if not 1024 <= port <= 65535:
        raise CourseError(f"port must be 1024..65535, got {port}")
    profile = dds_config.discovery_server_profile(processes.log_dir(), lease_s)
    argv = processes.program_argv(_server_binary(), "-i", "0", "-l", "127.0.0.1", "-p", str(port),
                                  "-x", profile)
    child = processes.start(SERVER_LABEL, argv, group=SERVER_GROUP, channel=False,
                            stop_signal=signal.SIGTERM)
    server = DiscoveryServer(port, child, lease_s, profile)
    if not (poll_until(lambda: server.ready() or not server.alive, timeout) and server.alive):
        server.stop()
        raise CourseError(f"the discovery server did not listen on UDP port {port} within {timeout:g} s. "
                          f"Its output:\n{child.output_tail(1500)}")
    return server


def stop_discovery_servers() -> None:
    """Stop and reap the discovery server this kernel started, if any."""
    processes.stop([SERVER_LABEL], group=SERVER_GROUP)

