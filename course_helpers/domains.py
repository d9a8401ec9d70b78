"""Pick a ROS domain for this kernel and keep discovery on this machine (chapters 00 and 07).

Every kernel or test worker reserves a domain ID that no other running kernel on
the machine holds, with a lock file that the operating system releases when the
process exits. A user who sets ``ROS_DOMAIN_ID`` keeps full control.
"""

from __future__ import annotations

import fcntl
import os
import tempfile
from dataclasses import dataclass

from .errors import CourseError

# Domain IDs 0..101 are safe on Linux for the default port mapping; 0 is what
# every other ROS program uses, so the course starts at 1.
FIRST_DOMAIN = 1
LAST_DOMAIN = 101
LOCK_DIR = os.path.join(tempfile.gettempdir(), f"ros2-course-domains-{os.getuid()}")


@dataclass
class DomainChoice:
    """The domain a runtime uses, and who chose it ('user' or 'automatic')."""

    domain_id: int
    source: str
    discovery_range: str


_held: dict[int, int] = {}  # domain -> lock file descriptor, held for the life of the process
_kernel_domain: list[int] = []  # the domain choose_domain() reserved for this process


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
    """Reserve a domain no other course process holds (and not in ``exclude``) until this one exits.

    The kernel's own domain comes from here; chapter 07 reserves a second one to show isolation.
    """
    os.makedirs(LOCK_DIR, exist_ok=True)
    span = LAST_DOMAIN - FIRST_DOMAIN + 1
    start = os.getpid() % span
    for offset in range(span):
        domain = FIRST_DOMAIN + (start + offset) % span
        if domain in _held or domain in exclude:
            continue
        fd = os.open(os.path.join(LOCK_DIR, f"domain-{domain}.lock"), os.O_RDWR | os.O_CREAT)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode())
        _held[domain] = fd
        return domain
    raise CourseError(
        f"all ROS domains {FIRST_DOMAIN}-{LAST_DOMAIN} are held by other course kernels on "
        "this machine; shut some kernels down, or set ROS_DOMAIN_ID yourself."
    )
