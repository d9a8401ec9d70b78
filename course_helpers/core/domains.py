"""A ROS domain of its own for every kernel, test worker and student on the machine (chapters 00, 07).

Every course process that needs a domain reserves one that no other course process on the
machine holds, whoever runs it. A reservation is a listening Unix socket bound to an abstract
name, ``@ros2-course-domain-<N>`` (Linux's abstract namespace: no file, no directory). Linux
gives each name to one socket at a time and frees it the moment its process exits, however it
exits. So

* nothing on disk decides a reservation: there is no file another user could delete, chmod,
  pre-create or point elsewhere, and ``TMPDIR`` plays no part;
* a crashed kernel leaves nothing to clean;
* the only way to keep a domain from others is a live process holding its socket, which
  ``ss -xlp | grep ros2-course-domain`` shows with its PID, and
  ``python -m course_helpers.core.domains`` with its user and command (docs/classroom.md).

Abstract names belong to a network namespace: on a classroom server all students share one, a
Kubernetes pod or a container with its own network has its own (and its own loopback, which is
what really separates students there). On one host, domains keep honest kernels apart; a user
who sets ``ROS_DOMAIN_ID`` on purpose keeps full control and can join any domain.

A reserved domain starts without the shared-memory ports that earlier processes left in it
(:mod:`.shm_ports`). Discovery stays on this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``)
unless the user chose another range.
"""

from __future__ import annotations

import errno
import os
import socket
from dataclasses import dataclass

from course_helpers.core.errors import CourseError
from course_helpers.core.shm_ports import remove_dead_segments, remove_stale_ports

# Domain IDs 0..101 are safe on Linux for the default port mapping; 0 is what every other
# ROS program uses, so the course starts at 1.
FIRST_DOMAIN = 1
LAST_DOMAIN = 101
SOCKET_PREFIX = "ros2-course-domain-"  # + the domain: an abstract Unix socket name


@dataclass
class DomainChoice:
    """The domain a runtime uses, and who chose it ('user' or 'automatic')."""

    domain_id: int
    source: str
    discovery_range: str


_held: dict[int, socket.socket] = {}  # domain -> its bound socket, held for the life of the process
_kernel_domain: list[int] = []  # the domain choose_domain() reserved for this process
_spare_domain: list[int] = []  # a second domain, for chapter 07's isolation demo


def socket_name(domain: int) -> str:
    """The abstract socket name that reserves ``domain`` (``ss -xlp`` shows it with a leading '@')."""
    return f"{SOCKET_PREFIX}{domain}"


def _bind(domain: int) -> socket.socket | None:
    """A listening socket bound to ``domain``'s name, or None if another process holds the name.

    The socket is not inherited by child programs (Python sockets are close-on-exec), so a
    course child never keeps its kernel's domain after the kernel has gone.
    """
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.bind(b"\0" + socket_name(domain).encode())
    except OSError as exc:
        sock.close()
        if exc.errno == errno.EADDRINUSE:
            return None
        raise CourseError(f"could not reserve ROS domain {domain}: binding the abstract socket "
                          f"@{socket_name(domain)} failed ({exc})") from None
    sock.listen(1)  # listening, so that `ss -xlp` lists it with its owner; nobody ever connects
    return sock


def choose_domain() -> DomainChoice:
    """Return the domain for this process, reserving a free one if the user set none.

    Sets ``ROS_DOMAIN_ID`` and ``ROS_AUTOMATIC_DISCOVERY_RANGE`` in ``os.environ`` so
    child-process nodes inherit them.
    """
    user_value = os.environ.get("ROS_DOMAIN_ID")
    if user_value is not None and not (_kernel_domain and user_value == str(_kernel_domain[0])):
        domain = parse_domain_id(user_value)
        source = "user"
    else:
        if not _kernel_domain:
            remove_dead_segments()  # what killed processes left in /dev/shm, once per kernel
            _kernel_domain.append(reserve_domain())
        domain = _kernel_domain[0]
        source = "automatic"
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    return DomainChoice(domain, source, os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"])


def parse_domain_id(value) -> int:
    """Return ``value`` as a domain ID, or raise :class:`CourseError` if it is not 0..232."""
    try:
        domain = int(value)
    except (TypeError, ValueError):
        domain = -1
    if not 0 <= domain <= 232:
        raise CourseError(
            f"ROS_DOMAIN_ID must be a whole number from 0 to 232 (0-101 is safe on Linux), "
            f"got {value!r}"
        )
    return domain


def reserve_domain(exclude: tuple[int, ...] = ()) -> int:
    """Reserve a domain no other course process on the machine holds, until this process exits.

    The kernel's own domain comes from here; chapter 07 reserves a second one to show isolation.
    """
    span = LAST_DOMAIN - FIRST_DOMAIN + 1
    start = os.getpid() % span
    for offset in range(span):
        domain = FIRST_DOMAIN + (start + offset) % span
        if domain in _held or domain in exclude:
            continue
        sock = _bind(domain)
        if sock is None:
            continue
        _held[domain] = sock
        remove_stale_ports(domain)  # no course participant uses it: start it without old ports
        return domain
    raise CourseError(
        f"all ROS domains {FIRST_DOMAIN}-{LAST_DOMAIN} are held by other course processes on this "
        "machine. Shut some kernels down (the Running panel), or set ROS_DOMAIN_ID yourself. An "
        f"administrator sees who holds them with: sudo ss -xlp | grep {SOCKET_PREFIX}"
    )


def reserve_spare_domain() -> int:
    """A second domain for this process, reserved like its own; re-running returns the same one."""
    if not _spare_domain:
        own = os.environ.get("ROS_DOMAIN_ID")
        _spare_domain.append(reserve_domain(exclude=(int(own),) if own and own.isdigit() else ()))
    return _spare_domain[0]


def held_here(domain: int) -> bool:
    """True if this process holds ``domain``'s reservation (its socket is bound to the name)."""
    sock = _held.get(domain)
    if sock is None or sock.fileno() < 0:
        return False
    return sock.getsockname() in (b"\0" + socket_name(domain).encode(), "\0" + socket_name(domain))


def domain_free(domain: int) -> bool:
    """True if no process on the machine holds ``domain`` (tried by binding its name, released at once)."""
    sock = _bind(domain)
    if sock is None:
        return False
    sock.close()
    return True


def domain_holders(domain: int) -> set[int]:
    """PIDs of the processes that hold ``domain``'s socket, among those this user may inspect."""
    import psutil

    wanted = "@" + socket_name(domain)
    holders = set()
    for proc in psutil.process_iter():
        try:
            if any(c.laddr == wanted for c in proc.net_connections(kind="unix")):
                holders.add(proc.pid)
        except psutil.Error:
            continue
    return holders


def domains_held_by(proc) -> list[int]:
    """The course domains a process holds (its listening sockets with a reservation's name), sorted.

    ``proc`` is a ``psutil.Process``; raises ``psutil.Error`` if it is gone or may not be inspected.
    """
    prefix = "@" + SOCKET_PREFIX
    numbers = {c.laddr[len(prefix):] for c in proc.net_connections(kind="unix")
               if isinstance(c.laddr, str) and c.laddr.startswith(prefix)}
    return sorted(int(n) for n in numbers if n.isdigit())


def held_domains() -> dict[int, list[str]]:
    """Every course domain some process holds: ``{domain: ['user pid command', ...]}``.

    A holder this user may not inspect (another user's, without root) is shown as unknown.
    """
    import psutil

    found: dict[int, list[str]] = {}
    for proc in psutil.process_iter():
        try:
            mine = domains_held_by(proc)
            if mine:
                described = f"{proc.username()} {proc.pid} {' '.join(proc.cmdline())[:100]}"
                for domain in mine:
                    found.setdefault(domain, []).append(described)
        except psutil.Error:
            continue
    held = {}
    for domain in range(FIRST_DOMAIN, LAST_DOMAIN + 1):
        if domain in found:
            held[domain] = found[domain]
        elif not domain_free(domain):
            held[domain] = ["unknown: another user's process (run as root to see it)"]
    return held


def main() -> int:
    """``python -m course_helpers.core.domains``: who holds which course domain (root sees everyone)."""
    held = held_domains()
    for domain, holders in held.items():
        for holder in holders:
            print(f"domain {domain:>3}  {holder}")
    print(f"{len(held)} of {LAST_DOMAIN - FIRST_DOMAIN + 1} course domains held")
    return 0


def nodes_in_domain(domain_id: int, wait_s: float = 1.5, expect: list[str] | tuple = ()) -> list[str]:
    """Full names of the nodes visible in ``domain_id``, seen by a short-lived participant.

    Waits ``wait_s`` seconds for discovery (less if every name in ``expect`` shows up first).
    The probe's own node is hidden (its name starts with '_') and left out.
    """
    from rclpy.context import Context
    from rclpy.node import Node

    from course_helpers.core.dds_config import init_context
    from course_helpers.core.names import node_full_names
    from course_helpers.core.waiting import poll_until

    domain_id = parse_domain_id(domain_id)
    context = Context()
    init_context(context, domain_id)
    try:
        probe = Node("_domain_probe", context=context, enable_rosout=False,
                     start_parameter_services=False)
        try:
            seen: list[str] = []

            def look() -> bool:
                seen[:] = node_full_names(probe.get_node_names_and_namespaces())
                return bool(expect) and all(name in seen for name in expect)

            poll_until(look, wait_s, period=0.05)
            return seen
        finally:
            probe.destroy_node()
    finally:
        context.try_shutdown()


if __name__ == "__main__":
    raise SystemExit(main())
