"""How the course's participants are configured for Fast DDS: discovery timing and transports.

Every course participant (the kernel's, each child's) reads a Fast DDS XML profile named by
``FASTRTPS_DEFAULT_PROFILES_FILE`` (the variable Fast DDS 2.14 reads). Three settings in it make a
node in a new process visible within a fraction of a second, and the order of a child's peers
makes the kernel hear it at once (chapter 07 measures them; a trace of the RTPS traffic and the
Fast DDS 2.14 sources explain them):

* **Announcements every** ``ANNOUNCEMENT_S`` **(default 3 s).** A new participant announces itself
  before it listens: ``RTPSParticipantImpl::enable()`` sends the first announcement and only then
  registers its receivers, so the instant answer of the participants already running is dropped.
  The newcomer learns of each one only at its next periodic announcement.
* **The graph reader asks at once.** Which nodes live in a participant travels on the
  ``ros_discovery_info`` topic, reliable and transient-local. A reader asks a newly matched writer
  for its history after ``initialAcknackDelay`` (Fast DDS default 70 ms); the course's graph reader
  asks after ``GRAPH_ACKNACK_S``, in both directions of every new pair.
* **Shared-memory health check of** ``SHM_HEALTH_CHECK_MS`` **(default 1000 ms).** The first time a
  process writes to another participant's shared-memory port it checks that the port's listeners
  are alive; when the check falls just after another process's check, it sleeps a third of this
  timeout and checks again. That sleep holds up the new process's sending, discovery included.
  A port keeps the timeout of the process that created it, and a port outlives its listener while
  another process holds it (:mod:`.shm_ports`): next to running programs with Fast DDS's defaults,
  a course process can still meet the 333 ms wait.
* **The kernel is told last.** A child announces itself to the discovery ports of participant ids
  31 down to 0, in that order (a child's profile lists them; see the port slots below). The kernel's
  participant is the first in its domain, so it holds id 0, and its instant answer usually arrives
  after the child has sent its last announcement and started listening, instead of being dropped
  while the child still sends to the ports after it. A dropped answer costs the rest of an
  announcement period, then the endpoint readers' first request (70 ms, a Fast DDS default no
  profile reaches), then the 100 ms endpoint answer. Measured with
  ``benchmarks/discovery_latency.py``'s kernel set-up, idle: the kernel saw a child after 0.21-0.30 s
  instead of 0.13-0.15 s in 30 of 60 starts with the ids counted upwards, and in 38 of 220 with this
  order. The answer still comes too early at times (a trace shows one 0.1-0.2 ms after the child's
  last send, before the child had registered its receivers). Two children meet in whatever order
  their slots give, and miss it more often.

**Replies to early requests.** A client may see a service, and send its request, before the server
has matched the client's reply reader: each side matches when the other's announcement of the
endpoint reaches it, and the two announcements travel separately. rmw_fastrtps then holds the reply
until that reader matches, for at most the reply writer's ``max_blocking_time`` (Fast DDS default
100 ms), and drops it after that with "client will not receive response". The reader of a client
whose request arrived matches for certain, only later on a busy machine, so the course's ``service``
writer profile bounds that wait like every wait for what happens for certain: ``REPLY_WAIT_S`` is
:data:`course_helpers.core.waiting.HANG_S`, which ends a hang and says nothing about speed. A bound
of 1 s dropped a correct server's reply in a fresh-clone CI run, and a checker then reported "no
answer". The wait costs nothing once the reader has matched; a server blocks for the whole bound
only for a client whose reply reader never matches (a reply QoS it cannot accept: the course's
checkers test compatibility first, with rclpy's own check).

The shared-memory setting is a transport setting, and for the LOCALHOST discovery range rmw_fastrtps
builds the transports itself (with the 1000 ms default). So the course's profile states that same
localhost-only set-up: shared memory, UDP on 127.0.0.1 only, 127.0.0.1 as the initial peer for 32
participant ids, no multicast. :func:`init_context` starts a course context with the range
``SYSTEM_DEFAULT``, which leaves the transports to the profile; ``ROS_AUTOMATIC_DISCOVERY_RANGE``
stays ``LOCALHOST`` in the environment, for children and other programs.

**Other ranges** (a child with ``OFF``, a user's ``SUBNET``) get the timing settings only, and
rmw_fastrtps sets up the transports as for any ROS program.

**UDP only.** ``udp_loopback_env(directory)`` is the environment for a child whose samples must
cross the loopback network instead of shared memory (chapter 07's transports, the QoS lab's UDP
mode): the same profile without shared memory.

**Fast DDS defaults.** ``default_discovery_env(directory)`` gives a child Fast DDS's own timing,
for comparisons (chapter 07, the benchmark).

**A short lease.** ``short_lease_env(directory, lease_s)`` is the course's profile for this range with
another lease: peers drop a crashed child that long after its last announcement (chapter 01).

**A discovery server's lease.** ``fast-discovery-server`` ignores ``FASTRTPS_DEFAULT_PROFILES_FILE``
(it starts from a default-built participant QoS) and reads a profile only when given ``-x FILE``.
``discovery_server_profile(directory, lease_s)`` writes one that keeps the server a server and sets its
lease and announcements (chapter 07 kills a server and needs its clients to drop it soon).

**A port slot per child.** ``slot_profile_env(directory, slot, domain_id, lease_s)`` is the localhost
profile (with its lease) on the unicast ports of participant id ``slot``; the process layer gives each
child a slot of its own, so that it never takes over the ports a killed child left (:mod:`.port_slots`).

Profiles are written into a folder private to the process (``processes.log_dir()``), never to a
shared, predictable path that another user could create first.

A user who set ``FASTRTPS_DEFAULT_PROFILES_FILE`` keeps their own profile.
"""

from __future__ import annotations

import os
import re
import tempfile
import threading
from contextlib import contextmanager

from course_helpers.core.errors import CourseError
from course_helpers.core.mapped_files import shm_files
from course_helpers.core.udp_sockets import RTPS_PORTS, discovery_port, udp_sockets
from course_helpers.core.waiting import HANG_S

PROFILE_ENV = "FASTRTPS_DEFAULT_PROFILES_FILE"
RANGE_ENV = "ROS_AUTOMATIC_DISCOVERY_RANGE"
ANNOUNCEMENT_S = 0.1  # s; the course's periodic participant announcement
DEFAULT_ANNOUNCEMENT_S = 3.0  # s; Fast DDS's default, what participants outside the course use
LEASE_S = 20  # s; how long a silent participant is kept (Fast DDS's default)
GRAPH_TOPIC = "ros_discovery_info"  # rmw's topic of which nodes live in which participant
GRAPH_ACKNACK_S = 0.002  # s; the graph reader's first request to a new writer
DEFAULT_ACKNACK_S = 0.07  # s; Fast DDS's default initialAcknackDelay
SHM_HEALTH_CHECK_MS = 300  # ms; the course's shared-memory port health-check timeout
DEFAULT_SHM_HEALTH_CHECK_MS = 1000  # ms; Fast DDS's default (and what rmw's LOCALHOST set-up uses)
SERVICE_PROFILE = "service"  # the profile rmw_fastrtps reads for every service's reply writer
REPLY_WAIT_S = HANG_S  # s; how long a server waits for the client's reply reader (Fast DDS default: 0.1 s)
PEER_IDS = 32  # participant ids on 127.0.0.1 that an announcement reaches (as rmw's LOCALHOST)
# Discovery between two participants of one process goes through the transports, as between processes;
# only user data takes Fast DDS's in-process shortcut. With the shortcut for discovery too (Fast DDS's
# default, FULL), a kernel's participant stopped hearing which readers its sandboxes' kept participant
# (kept_contexts.py) made: after a few hundred sandboxes beside two busy loops, the kernel's graph listed
# a new relay's reply writer but never its request reader, for a minute and more, so no client of it ever
# became ready (Fast DDS 2.14.5; RTPSDomainImpl::should_intraprocess_between).
INTRAPROCESS_DELIVERY = "USER_DATA_ONLY"

# the profiles the course writes, by file name
LOCALHOST_PROFILE = "course_localhost.xml"  # shared memory + UDP on 127.0.0.1, tuned timing
TIMING_PROFILE = "course_timing.xml"  # tuned timing only, for ranges other than LOCALHOST
UDP_PROFILE = "course_udp_loopback.xml"  # UDP on 127.0.0.1 only, tuned timing
DEFAULTS_PROFILE = "fastdds_default_discovery.xml"  # Fast DDS's timing, for comparisons
SERVER_PROFILE_STEM = "course_discovery_server_lease"  # + _<ms>ms.xml
LEASE_PROFILE_STEMS = ("course_localhost_lease", "course_timing_lease")  # + _<ms>ms.xml, by range
SLOT_PROFILE_STEM = "course_localhost_slot"  # + _<slot>_domain<d>.xml: the localhost profile on a port slot
# the localhost profiles a child gets a port slot of: plain or with a short lease, maybe on a parent's slot
_SLOTTABLE = re.compile(r"course_localhost(?:_lease_(\d+)ms)?(?:_slot_\d+_domain\d+)?\.xml")
_CHOSEN_BY_RANGE = (LOCALHOST_PROFILE, TIMING_PROFILE)  # picked per process, may be replaced
MIN_LEASE_S, MAX_LEASE_S = 0.5, 60.0  # s; a lease must be several announcements long

_environ_lock = threading.RLock()  # held while a context starts with a temporary range


def _duration(tag: str, seconds: float) -> str:
    whole = int(seconds)
    return f"<{tag}><sec>{whole}</sec><nanosec>{round((seconds - whole) * 1e9)}</nanosec></{tag}>"


def profile_xml(transports: tuple[str, ...] = ("SHM", "UDPv4"), tuned: bool = True,
                lease_s: float = LEASE_S, slot: int = 0, domain_id: int = 0) -> str:
    """A Fast DDS profile: the default participant, and the graph topic's reader.

    Args:
        transports: the transports of a localhost-only participant (``"SHM"``, ``"UDPv4"``), or ()
            to leave transports and peers to rmw_fastrtps.
        tuned: the course's timing; False gives Fast DDS's defaults (for comparisons).
        lease_s: how long peers keep the participant after its last announcement.
        slot: the participant's unicast ports are those of participant id ``slot`` (and up), by the
            port offsets; 0 leaves RTPS's own (:mod:`.port_slots` says why a child gets another).
        domain_id: with a slot, the domain whose ports of participant ids 0-31 are the initial peers,
            listed from id 31 down to 0 so that the kernel is told last (without a slot, Fast DDS
            would count them from the moved offsets and miss ids below ``slot``).
    """
    unknown = set(transports) - {"SHM", "UDPv4"}
    if unknown:
        raise ValueError(f"transports must be 'SHM' and/or 'UDPv4', got {sorted(unknown)}")
    announcement = ANNOUNCEMENT_S if tuned else DEFAULT_ANNOUNCEMENT_S
    health_ms = SHM_HEALTH_CHECK_MS if tuned else DEFAULT_SHM_HEALTH_CHECK_MS
    lines = ['<?xml version="1.0" encoding="UTF-8" ?>',
             '<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">',
             f"  <library_settings><intraprocess_delivery>{INTRAPROCESS_DELIVERY}</intraprocess_delivery>"
             "</library_settings>"]
    if transports:
        lines.append("  <transport_descriptors>")
        if "SHM" in transports:
            lines += ["    <transport_descriptor>", "      <transport_id>course_shm</transport_id>",
                      "      <type>SHM</type>",
                      f"      <healthy_check_timeout_ms>{health_ms}</healthy_check_timeout_ms>",
                      "    </transport_descriptor>"]
        if "UDPv4" in transports:
            lines += ["    <transport_descriptor>", "      <transport_id>course_udp</transport_id>",
                      "      <type>UDPv4</type>",
                      f"      <maxInitialPeersRange>{PEER_IDS}</maxInitialPeersRange>",
                      "      <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>",
                      "    </transport_descriptor>"]
        lines.append("  </transport_descriptors>")
    lines += ['  <participant profile_name="course_participant" is_default_profile="true">', "    <rtps>"]
    if slot:  # RTPS's unicast offsets d1 (discovery, 10) and d3 (data, 11), moved by 2 per id
        lines.append(f"      <port><offsetd1>{10 + 2 * slot}</offsetd1>"
                     f"<offsetd3>{11 + 2 * slot}</offsetd3></port>")
    if transports:
        ids = "".join(f"<transport_id>course_{t.lower().removesuffix('v4')}</transport_id>"
                      for t in transports)
        lines += [f"      <userTransports>{ids}</userTransports>",
                  "      <useBuiltinTransports>false</useBuiltinTransports>"]
    lines += ["      <builtin>", "        <discovery_config>",
              f"          {_duration('leaseDuration', lease_s)}",
              f"          {_duration('leaseAnnouncement', announcement)}",
              "        </discovery_config>"]
    if transports:  # unicast discovery only, to 127.0.0.1: no multicast
        if slot:  # the discovery ports of participant ids 31 down to 0: the kernel's (id 0) last
            ports = (discovery_port(domain_id, i) for i in reversed(range(PEER_IDS)))
            peers = "".join(f"<locator><udpv4><address>127.0.0.1</address><port>{port}</port></udpv4>"
                            "</locator>" for port in ports)
        else:  # port 0: Fast DDS fills in those of participant ids 0-31 (maxInitialPeersRange)
            peers = "<locator><udpv4><address>127.0.0.1</address></udpv4></locator>"
        lines += ["        <metatrafficUnicastLocatorList><locator><udpv4/></locator>"
                  "</metatrafficUnicastLocatorList>",
                  f"        <initialPeersList>{peers}</initialPeersList>"]
    lines += ["      </builtin>", "    </rtps>", "  </participant>"]
    if tuned:
        lines += [f'  <data_reader profile_name="{GRAPH_TOPIC}">',
                  f"    <times>{_duration('initialAcknackDelay', GRAPH_ACKNACK_S)}</times>",
                  "  </data_reader>",
                  f'  <data_writer profile_name="{SERVICE_PROFILE}">',
                  f"    <qos><reliability>{_duration('max_blocking_time', REPLY_WAIT_S)}</reliability></qos>",
                  "  </data_writer>"]
    lines.append("</profiles>")
    return "\n".join(lines) + "\n"


def write_profile(directory: str, name: str, text: str) -> str:
    """Write a profile into ``directory``, a folder private to this process (``processes.log_dir()``),
    once per content, and return its path. A child never reads a half-written file: it is written
    beside and then renamed into place."""
    path = os.path.join(directory, name)
    try:
        with open(path, encoding="utf-8") as handle:
            if handle.read() == text:
                return path
    except OSError:
        pass
    handle, partial = tempfile.mkstemp(dir=directory, prefix=f".{name}.", text=True)
    with os.fdopen(handle, "w", encoding="utf-8") as out:
        out.write(text)
    os.replace(partial, path)
    return path


def _states_transports(path: str) -> bool:
    """True for the course's profiles that set up localhost-only transports themselves."""
    name = os.path.basename(path)
    return name in (LOCALHOST_PROFILE, UDP_PROFILE) or name.startswith(
        (LEASE_PROFILE_STEMS[0] + "_", SLOT_PROFILE_STEM + "_"))


def slot_lease(env: dict[str, str]) -> float | None:
    """The lease, in seconds, of the course's localhost profile (plain, a short lease, or either on a
    parent's slot) that a child started with ``env`` would read; None for any other profile or range.
    Such a child gets a port slot of its own (:mod:`.port_slots`)."""
    match = _SLOTTABLE.fullmatch(os.path.basename(env.get(PROFILE_ENV, "")))
    if env.get(RANGE_ENV, "").upper() != "LOCALHOST" or not match:
        return None
    return int(match.group(1)) / 1000 if match.group(1) else LEASE_S


def slot_profile_env(directory: str, slot: int, domain_id: int, lease_s: float = LEASE_S) -> dict[str, str]:
    """The environment of a child whose participants listen on the ports of port slot ``slot`` of
    ``domain_id``."""
    stem = SLOT_PROFILE_STEM
    if lease_s != LEASE_S:
        stem = f"{LEASE_PROFILE_STEMS[0]}_{round(lease_s * 1000)}ms_slot"
    text = profile_xml(lease_s=lease_s, slot=slot, domain_id=domain_id)
    return {PROFILE_ENV: write_profile(directory, f"{stem}_{slot}_domain{domain_id}.xml", text)}


def _is_localhost_range() -> bool:
    return os.environ.get(RANGE_ENV, "").upper() == "LOCALHOST"


def apply_course_discovery(directory: str) -> str:
    """Point ``FASTRTPS_DEFAULT_PROFILES_FILE`` at the course's profile for this process's range.

    Call it before the process's first participant exists. The LOCALHOST range gets the
    localhost-only profile, other ranges the timing-only one. A profile set by the user, or
    chosen for a child (UDP only, Fast DDS defaults), is kept. Returns the profile in use.
    """
    current = os.environ.get(PROFILE_ENV)
    if not current or os.path.basename(current) in _CHOSEN_BY_RANGE:
        if _is_localhost_range():
            os.environ[PROFILE_ENV] = write_profile(directory, LOCALHOST_PROFILE, profile_xml())
        else:
            os.environ[PROFILE_ENV] = write_profile(directory, TIMING_PROFILE, profile_xml(()))
    return os.environ[PROFILE_ENV]


LATE_PROFILE = ("note: this process made a DDS participant (rclpy.init() and a node) before the course "
                "started ROS, and Fast DDS reads its settings only once, so the course's discovery profile "
                "does not apply in this kernel: nodes of other processes may take seconds to show. Restart "
                "the kernel and run the chapter's first cell before your own rclpy.init().")


def profile_comes_too_late() -> bool:
    """Whether the course's profile would come too late for this process: no profile is set yet, and a
    participant already exists here (Fast DDS's shared memory is mapped, or a UDP socket is bound in
    the RTPS port range). Fast DDS 2.14 reads ``FASTRTPS_DEFAULT_PROFILES_FILE`` once per process, when
    the first participant is made (``DomainParticipantFactory::load_profiles``); children still get it."""
    if os.environ.get(PROFILE_ENV):
        return False
    return bool(shm_files()) or any(RTPS_PORTS[0] <= port < RTPS_PORTS[1] for _, port in udp_sockets())


@contextmanager
def _range_left_to_profile():
    """While a participant is created: the range SYSTEM_DEFAULT, if the profile states LOCALHOST itself."""
    with _environ_lock:
        if not (_is_localhost_range() and _states_transports(os.environ.get(PROFILE_ENV, ""))):
            yield
            return
        saved = os.environ[RANGE_ENV]
        os.environ[RANGE_ENV] = "SYSTEM_DEFAULT"
        try:
            yield
        finally:
            os.environ[RANGE_ENV] = saved


def init_context(context, domain_id: int, args: list[str] | None = None) -> None:
    """``rclpy.init`` for a course context: its participant takes the course profile's transports.

    rclpy's signal handlers are not installed (an interrupt stops a cell, never ROS).
    """
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    with _range_left_to_profile():
        rclpy.init(args=args, context=context, domain_id=domain_id,
                   signal_handler_options=SignalHandlerOptions.NO)


def environment_snapshot() -> dict[str, str]:
    """A copy of ``os.environ`` as children should inherit it (never the temporary range)."""
    with _environ_lock:
        return dict(os.environ)


def default_discovery_env(directory: str) -> dict[str, str]:
    """Environment for a child with Fast DDS's own discovery timing and rmw's transports (comparisons)."""
    return {PROFILE_ENV: write_profile(directory, DEFAULTS_PROFILE, profile_xml((), tuned=False))}


def udp_loopback_env(directory: str) -> dict[str, str]:
    """Environment variables that make a child's participant use UDP on 127.0.0.1 only.

    Writes the XML profile into ``directory`` and returns the variables to pass as ``env=`` to
    ``rt.spawn``.
    """
    path = write_profile(directory, UDP_PROFILE, profile_xml(("UDPv4",)))
    return {RANGE_ENV: "LOCALHOST", PROFILE_ENV: path}


def _check_lease(lease_s) -> None:
    if isinstance(lease_s, bool) or not isinstance(lease_s, (int, float)) or not (
            MIN_LEASE_S <= lease_s <= MAX_LEASE_S):
        raise CourseError(f"lease_s must be {MIN_LEASE_S:g}..{MAX_LEASE_S:g} seconds, got {lease_s!r}")


def discovery_server_profile(directory: str, lease_s: float) -> str:
    """Write the profile for ``fast-discovery-server -x`` (a SERVER announcing a lease of ``lease_s``
    every ``ANNOUNCEMENT_S``) into ``directory`` and return its path. Addresses come from the command
    line (``-l``, ``-p``), which takes precedence over the file."""
    _check_lease(lease_s)
    text = "\n".join([
        '<?xml version="1.0" encoding="UTF-8" ?>',
        '<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">',
        '  <participant profile_name="course_discovery_server" is_default_profile="true">',
        "    <rtps>", "      <builtin>", "        <discovery_config>",
        "          <discoveryProtocol>SERVER</discoveryProtocol>",
        f"          {_duration('leaseDuration', lease_s)}",
        f"          {_duration('leaseAnnouncement', ANNOUNCEMENT_S)}",
        "        </discovery_config>", "      </builtin>", "    </rtps>", "  </participant>",
        "</profiles>"]) + "\n"
    return write_profile(directory, f"{SERVER_PROFILE_STEM}_{round(lease_s * 1000)}ms.xml", text)


def short_lease_env(directory: str, lease_s: float) -> dict[str, str]:
    """Environment for a child whose participant announces a lease of ``lease_s`` seconds.

    Peers drop a participant that stays silent longer than its lease (Fast DDS's default: 20 s).
    Everything else is the course's profile for this process's discovery range. Writes the profile
    into ``directory`` and returns the variables to pass as ``env=`` to ``rt.spawn``.
    """
    _check_lease(lease_s)
    localhost = _is_localhost_range()
    stem = LEASE_PROFILE_STEMS[0] if localhost else LEASE_PROFILE_STEMS[1]
    text = profile_xml(("SHM", "UDPv4") if localhost else (), lease_s=lease_s)
    return {PROFILE_ENV: write_profile(directory, f"{stem}_{round(lease_s * 1000)}ms.xml", text)}
