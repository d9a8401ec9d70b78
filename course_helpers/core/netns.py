"""Private network namespaces for child processes: a lossy link, two machines on one box.

A network namespace has its own interfaces, addresses, ports and firewall, starting with a loopback
interface that is down. The course makes one with ``unshare`` and keeps it open with a sleeping
child of the process layer (the *holder*); other children join it with ``nsenter``. So everything
in a namespace is a course child: it dies with the kernel and stops with its label, and when the
last process inside has ended, Linux removes the namespace with its interfaces and rules.

* As root: ``unshare -n`` (a network namespace of the machine's user namespace).
* As any other user: ``unshare -U -r -n``, a user namespace (in which this user counts as root)
  that owns the network namespace; ``nsenter -U -n --preserve-credentials`` joins both. A second
  namespace can share the first one's user namespace (:func:`create` with ``owner``), so that a veth
  pair may join the two (:func:`connect`).

Traffic stays inside: a new namespace has no route to anything outside it, and :func:`connect`
only joins two namespaces the course made.

Some systems do not allow it (Ubuntu 24.04's AppArmor default forbids unprivileged user
namespaces; a container may forbid ``unshare``). :func:`unavailable_reason` tries once per
process and says why in one line; callers disable what needs a namespace and show that line.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
import threading

from course_helpers.core import processes
from course_helpers.core.errors import CourseError
from course_helpers.core.waiting import poll_until

GROUP = "netns"  # the process-layer group of the holders
TOOLS = ("unshare", "nsenter", "ip", "nft")  # what every namespace needs (tc only for a rate limit)
READY_TIMEOUT_S = 10.0  # a holder must be inside its namespace by then
COMMAND_TIMEOUT_S = 20.0
APPARMOR_SWITCH = "/proc/sys/kernel/apparmor_restrict_unprivileged_userns"

_probe_lock = threading.Lock()
_probed: list[str | None] = []


def rootless() -> bool:
    """True when namespaces need a user namespace of their own (this process is not root)."""
    return os.geteuid() != 0


class NetworkNamespace:
    """A network namespace held open by the child process ``holder`` (see the module docstring)."""

    def __init__(self, label: str, holder: processes.ChildProcess, user_ns: bool):
        self.label = label
        self.holder = holder
        self.user_ns = user_ns  # joined together with a user namespace of its own (rootless)

    @property
    def pid(self) -> int:
        """The holder's process ID (``nsenter -t PID`` joins its namespaces)."""
        return self.holder.pid

    @property
    def alive(self) -> bool:
        """True while the holder keeps the namespace open."""
        return self.holder.alive

    def enter(self, argv: list[str]) -> list[str]:
        """``argv`` as a command that runs inside this namespace (same process: nsenter execs it)."""
        joins = ["-U", "-n", "--preserve-credentials"] if self.user_ns else ["-n"]
        return ["nsenter", "-t", str(self.pid), *joins, "--", *map(str, argv)]

    def run(self, *argv: str, check: bool = True) -> tuple[int, str]:
        """Run a command inside (``ip ...``, ``nft ...``) to its end: ``(exit code, output)``.

        With ``check`` a failure raises CourseError with the command and its output.
        """
        if not self.alive:
            raise CourseError(f"network namespace {self.label!r} is gone (its holder exited)")
        code, output = processes.run(self.enter(list(argv)), timeout=COMMAND_TIMEOUT_S)
        if check and code != 0:
            raise CourseError(f"`{' '.join(argv)}` failed in network namespace {self.label!r} "
                              f"(exit {code}): {output.strip()}")
        return code, output

    def ip_batch(self, commands: list[str]) -> None:
        """Run several ``ip`` commands (without the ``ip``) inside, as one process: ``ip -batch``.

        Raises CourseError naming the command that failed, with ip's output.
        """
        handle, path = tempfile.mkstemp(prefix="ip-batch-", suffix=".txt", dir=processes.log_dir())
        with os.fdopen(handle, "w", encoding="utf-8") as batch:
            batch.write("\n".join(commands) + "\n")
        try:
            self.run("ip", "-batch", path)
        finally:
            os.unlink(path)

    def start(self, label: str, argv: list[str], *, group: str = "node", env: dict | None = None,
              **options) -> processes.ChildProcess:
        """Start ``argv`` (from :func:`processes.python_target_argv`) inside as a course child."""
        return processes.start(label, self.enter(argv), group=group, env=env, **options)

    def received_bytes(self, interface: str = "lo") -> int:
        """Bytes ``interface`` inside this namespace has received so far (0 if it has none)."""
        try:
            with open(f"/proc/{self.pid}/net/dev", encoding="ascii") as handle:
                for line in handle:
                    name, _, data = line.partition(":")
                    if name.strip() == interface:
                        return int(data.split()[0])
        except (OSError, ValueError, IndexError):
            pass
        return 0

    def close(self) -> None:
        """Stop the holder. Linux removes the namespace once its last process has ended."""
        processes.stop([self.label], group=GROUP)

    def __repr__(self) -> str:
        state = "open" if self.alive else "closed"
        return f"<NetworkNamespace {self.label!r} holder={self.pid} {state}>"


def _net_ns(pid: int | str) -> str:
    try:
        return os.readlink(f"/proc/{pid}/ns/net")
    except OSError:
        return ""


def create(label: str, owner: NetworkNamespace | None = None) -> NetworkNamespace:
    """Make a network namespace with its loopback up; a namespace of the same label is closed first.

    Args:
        label: names the holder process (group ``'netns'``).
        owner: rootless only: make it inside ``owner``'s user namespace, so a veth pair can join
            the two (:func:`connect`). As root it changes nothing.

    Raises CourseError saying why, when a namespace cannot be made here.
    """
    missing = [tool for tool in TOOLS if shutil.which(tool) is None]
    if missing:
        raise CourseError(f"{', '.join(missing)} not found: install util-linux, iproute2 and nftables "
                          "(apt-get install util-linux iproute2 nftables)")
    user_ns = rootless()
    make = ["unshare", "-n", "--", "sleep", "infinity"]
    if user_ns and owner is None:
        make = ["unshare", "-U", "-r", "-n", "--", "sleep", "infinity"]
    elif user_ns:
        make = ["nsenter", "-t", str(owner.pid), "-U", "--preserve-credentials", "--", *make]
    holder = processes.start(label, processes.program_argv(*make), group=GROUP, channel=False)
    own = _net_ns("self")

    def inside() -> bool:  # unshare has made the namespace (and its user map) and become `sleep`
        try:
            with open(f"/proc/{holder.pid}/comm", encoding="utf-8") as handle:
                comm = handle.read().strip()
        except OSError:
            return not holder.alive
        return not holder.alive or (comm == "sleep" and _net_ns(holder.pid) not in ("", own))

    poll_until(inside, READY_TIMEOUT_S, period=0.01)
    if not holder.alive or not inside():
        lines = holder.output_tail(500).strip().splitlines()  # one line: the tool's last word
        output = lines[-1] if lines else f"no namespace after {READY_TIMEOUT_S:g} s"
        holder.stop(grace_s=1.0)
        raise CourseError(f"could not make a network namespace: {output}{_restriction_hint()}")
    namespace = NetworkNamespace(label, holder, user_ns)
    try:
        namespace.run("ip", "link", "set", "lo", "up")
    except CourseError:
        namespace.close()
        raise
    return namespace


def connect(a: NetworkNamespace, b: NetworkNamespace, address_a: str, address_b: str,
            prefix: int = 24) -> tuple[str, str]:
    """Join two namespaces with a veth pair, ``address_a``/``prefix`` in ``a`` and ``address_b`` in ``b``.

    Returns the interface names (``veth_a``, ``veth_b``). Multicast is routed over the link, as on a
    LAN, so that DDS's multicast discovery can use it.
    """
    def configure(name: str, address: str) -> list[str]:
        return [f"addr add {address}/{prefix} dev {name}", f"link set {name} up multicast on",
                f"route add 224.0.0.0/4 dev {name}"]

    a.ip_batch([f"link add veth_a type veth peer name veth_b netns {b.pid}", *configure("veth_a", address_a)])
    b.ip_batch(configure("veth_b", address_b))
    return "veth_a", "veth_b"


def _restriction_hint() -> str:
    if not rootless():
        return ""
    try:
        with open(APPARMOR_SWITCH, encoding="ascii") as handle:
            restricted = handle.read().strip() == "1"
    except OSError:
        restricted = False
    if restricted:
        return (" (AppArmor forbids unprivileged user namespaces here, Ubuntu 24.04's default: "
                "an administrator can allow them with sysctl kernel.apparmor_restrict_unprivileged_userns=0)")
    return " (this system does not let an ordinary user make a user namespace)"


def unavailable_reason() -> str | None:
    """None if this process can make network namespaces; else one line saying why not.

    Tries once per process (a namespace, its loopback up, an nftables table) and remembers.
    """
    with _probe_lock:
        if not _probed:
            _probed.append(_probe())
        return _probed[0]


def _probe() -> str | None:
    if not sys.platform.startswith("linux"):
        return f"network namespaces are a Linux feature; this is {sys.platform}"
    label = f"netns_probe_{os.getpid()}"
    try:
        namespace = create(label)
    except CourseError as error:
        return str(error)
    try:
        namespace.run("nft", "add", "table", "inet", "probe")
    except CourseError as error:
        return str(error)
    finally:
        namespace.close()
    return None
