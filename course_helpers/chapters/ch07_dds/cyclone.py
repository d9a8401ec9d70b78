"""Another vendor on the same graph: Eclipse Cyclone DDS (its Python binding, no ROS) in the kernel.

The lesson's program (participant, topic, reader, writer) is written in the notebook with the
``cyclonedds`` package; this module only sets up where it runs. :func:`cyclone_domain` creates,
in the kernel, the Cyclone DDS domain of the kernel's ROS domain id, configured to find the
course's participants; every participant the notebook then creates with that id joins it.

**How it finds the course's participants.** The course's Fast DDS participants discover each
other by unicast only (``core/dds_config.py``): over the loopback, no multicast, each announcing
itself to 127.0.0.1 on the unicast discovery ports of participant indexes 0 to ``PEER_IDS - 1``
(RTPS's port formula, the same for every vendor: 7400 + 250 x domain + 10 + 2 x index). Cyclone
DDS does the same with :func:`cyclone_config`:

* ``NetworkInterface name="lo"`` and ``AllowMulticast false``: the loopback, unicast only;
* ``ParticipantIndex auto`` (at most ``PEER_IDS - 1``): it takes a free index, so it listens on one
  of the ports the course's participants announce themselves to;
* ``Peer address="127.0.0.1"`` without a port: it announces itself to the ports of every index up
  to that maximum, where the course's participants listen.

So it joins the kernel's own domain as it is: ``%ros2`` and the live graph see it, and no network
namespace is needed (it also works where namespaces are not permitted). The other way, both sides
in a private namespace with multicast on, would need the course's participants to change their
discovery for it.

Re-running :func:`cyclone_domain` deletes the domain made before, and with it every participant,
topic, reader and writer in it, so a cell can be run again; the domain is also deleted when the
kernel exits (``atexit``). Cyclone then announces that its endpoints and participant leave: a
DATA(w[UD]) or DATA(p[UD]) that carries only the instance's key, serialized (the endpoint's or
participant's GUID as a parameter list, 28 bytes). Fast DDS 2.14 ignores a key-only DATA whose key
is longer than a 16-byte key hash (``MessageReceiver::proc_Submsg_Data``: "Ignoring Serialized
Payload for too large key-only data"), so the kernel's graph keeps Cyclone's endpoints until
Cyclone's lease runs out (10 s by default) and Fast DDS drops the silent participant.
"""

from __future__ import annotations

import atexit
from xml.sax.saxutils import escape

from course_helpers.core.dds_config import PEER_IDS
from course_helpers.core.errors import CourseError

PACKAGE = "cyclonedds"
INSTALL = "pip install cyclonedds==11.0.1 (environment.txt pins it; `make setup` installs it)"
PEER_ADDRESS = "127.0.0.1"

_domains: list = []  # the kernel's one Cyclone DDS domain, while it exists
_exit_hook: list[bool] = []


def cyclone_unavailable_reason() -> str | None:
    """None if Cyclone DDS's Python binding can be imported; else one line with the install."""
    try:
        import cyclonedds.domain  # noqa: F401  (the check is the import)
    except ImportError as exc:
        return f"Eclipse Cyclone DDS's Python binding is not installed ({exc}): {INSTALL}"
    return None


def cyclone_config(max_index: int = PEER_IDS - 1, trace_file: str | None = None) -> str:
    """The Cyclone DDS configuration (XML) that finds the course's participants (module docstring).

    With ``trace_file``, Cyclone DDS also writes its most detailed trace there (every discovery
    message it sends and receives): what a test reads when discovery did not happen.
    """
    tracing = [f"  <Tracing><Verbosity>finest</Verbosity><OutputFile>{escape(trace_file)}</OutputFile>"
               "</Tracing>"] if trace_file else []
    return "\n".join([
        '<CycloneDDS><Domain Id="any">',
        '  <General><Interfaces><NetworkInterface name="lo"/></Interfaces>',
        "           <AllowMulticast>false</AllowMulticast></General>",
        "  <Discovery><ParticipantIndex>auto</ParticipantIndex>",
        f"             <MaxAutoParticipantIndex>{int(max_index)}</MaxAutoParticipantIndex>",
        f'             <Peers><Peer address="{PEER_ADDRESS}"/></Peers></Discovery>',
        *tracing,
        "</Domain></CycloneDDS>"])


def cyclone_domain(rt, trace_file: str | None = None) -> int:
    """Create (again) the kernel's Cyclone DDS domain for ``rt``'s ROS domain; its id.

    Whatever Cyclone DDS entities this kernel made before are deleted first. Create participants
    with ``DomainParticipant(rt.domain.domain_id)`` after it. Raises CourseError (one line with the
    install) without the binding, or if a participant of that id exists that this did not set up.
    ``trace_file``: where Cyclone DDS writes its trace (:func:`cyclone_config`); None for no trace.
    """
    reason = cyclone_unavailable_reason()
    if reason is not None:
        raise CourseError(reason)
    from cyclonedds.core import DDSException
    from cyclonedds.domain import Domain

    close_cyclone()
    domain_id = rt.domain.domain_id
    try:
        _domains.append(Domain(domain_id, cyclone_config(trace_file=trace_file)))
    except DDSException as exc:
        raise CourseError(
            f"Cyclone DDS already has domain {domain_id} in this kernel, made with its default settings by "
            f"a DomainParticipant created before cyclone_domain(rt) ({exc}). Restart the kernel and run "
            "cyclone_domain(rt) before creating a participant.") from None
    if not _exit_hook:
        atexit.register(close_cyclone)
        _exit_hook.append(True)
    return domain_id


def cyclone_participants() -> int:
    """How many Cyclone DDS participants the kernel's domain holds now (0 without one)."""
    return len(_domains[0].get_participants()) if _domains else 0


def close_cyclone() -> None:
    """Delete the kernel's Cyclone DDS domain and everything in it (nothing to do without one).

    The binding deletes an entity when its Python object goes (``Entity.__del__``) and has no other
    delete; it is called here directly, so the domain goes now even if a cell still holds it.
    """
    while _domains:
        domain = _domains.pop()
        for participant in domain.get_participants():
            participant.__del__()
        domain.__del__()
