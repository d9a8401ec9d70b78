"""A ROS domain of its own for every kernel, test worker and student on the machine (chapters 00, 07).

Every course process that needs a domain reserves one that no other course process on
the machine holds, whoever runs it: the reservations are lock files in one shared, sticky
directory (``/tmp/ros2-course-domains``, mode 1777), and the operating system releases a
lock when its process exits. On a classroom server, where every student is a Unix user,
two students' kernels therefore never share a domain, even when their nodes talk over
UDP. A user who sets ``ROS_DOMAIN_ID`` keeps full control. A reserved domain starts without
the shared-memory ports that earlier processes left in it (:mod:`.shm_ports`). Discovery stays
on this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) unless the user chose another range.
"""

from __future__ import annotations

import errno
import fcntl
import os
import stat
import tempfile
from dataclasses import dataclass

from course_helpers.core.errors import CourseError
from course_helpers.core.shm_ports import remove_dead_segments, remove_stale_ports

# Domain IDs 0..101 are safe on Linux for the default port mapping; 0 is what every other
# ROS program uses, so the course starts at 1.
FIRST_DOMAIN = 1
LAST_DOMAIN = 101
LOCK_DIR_ENV = "COURSE_DOMAIN_LOCK_DIR"  # tests point it elsewhere; one machine, one directory
DEFAULT_LOCK_DIR = os.path.join(tempfile.gettempdir(), "ros2-course-domains")


@dataclass
class DomainChoice:
    """The domain a runtime uses, and who chose it ('user' or 'automatic')."""

    domain_id: int
    source: str
    discovery_range: str


_held: dict[int, int] = {}  # domain -> lock file descriptor, held for the life of the process
_kernel_domain: list[int] = []  # the domain choose_domain() reserved for this process
_spare_domain: list[int] = []  # a second domain, for chapter 07's isolation demo


def lock_dir() -> str:
    """The machine-wide directory of domain reservations (created sticky and world-writable)."""
    path = os.environ.get(LOCK_DIR_ENV) or DEFAULT_LOCK_DIR
    try:
        os.mkdir(path, 0o777)
        os.chmod(path, 0o1777)  # like /tmp: anyone may add a lock, nobody may remove another's
    except FileExistsError:
        pass
    info = os.stat(path)
    if not stat.S_ISDIR(info.st_mode):
        raise CourseError(f"{path} should be the course's domain-lock directory but is not a "
                          f"directory; remove it or set {LOCK_DIR_ENV} to another path.")
    return path


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


def _open_lock_file(path: str) -> int:
    """Open a lock file for reading, creating it if needed, whoever created it first.

    A file another user created in a sticky directory cannot be opened with O_CREAT on
    Linux (``fs.protected_regular``), so an existing file is opened without it; ``flock``
    needs only read access.
    """
    while True:
        try:
            return os.open(path, os.O_RDONLY)
        except FileNotFoundError:
            pass
        try:
            fd = os.open(path, os.O_RDONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            continue  # another process created it just now: open it as it is
        os.fchmod(fd, 0o644)  # whatever the umask: every user must be able to read it
        return fd


def reserve_domain(exclude: tuple[int, ...] = ()) -> int:
    """Reserve a domain no other course process on the machine holds, until this process exits.

    The kernel's own domain comes from here; chapter 07 reserves a second one to show isolation.
    """
    directory = lock_dir()
    span = LAST_DOMAIN - FIRST_DOMAIN + 1
    start = os.getpid() % span
    for offset in range(span):
        domain = FIRST_DOMAIN + (start + offset) % span
        if domain in _held or domain in exclude:
            continue
        try:
            fd = _open_lock_file(os.path.join(directory, f"domain-{domain}.lock"))
        except PermissionError:
            continue  # unreadable: treat as held by someone else
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno in (errno.EWOULDBLOCK, errno.EACCES):
                continue
            raise
        _held[domain] = fd
        remove_stale_ports(domain)  # no course participant uses it: start it without old ports
        return domain
    raise CourseError(
        f"all ROS domains {FIRST_DOMAIN}-{LAST_DOMAIN} are held by other course kernels on "
        "this machine; shut some kernels down, or set ROS_DOMAIN_ID yourself."
    )


def reserve_spare_domain() -> int:
    """A second domain for this process, reserved like its own; re-running returns the same one."""
    if not _spare_domain:
        own = os.environ.get("ROS_DOMAIN_ID")
        _spare_domain.append(reserve_domain(exclude=(int(own),) if own and own.isdigit() else ()))
    return _spare_domain[0]


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
