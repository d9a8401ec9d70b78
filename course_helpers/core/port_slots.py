"""Which ports a child's participants listen on: never those that a child of this process left a moment ago.

**Why.** Fast DDS names a participant's unicast ports after its participant id: ``7410 + 250 x domain +
2 x id`` for discovery and the next port for data, over UDP and shared memory alike. A new process
takes the lowest id whose ports are free. When a child ends without deleting its participant (killed,
or crashed), its shared-memory ports keep its listener registered, and the kernel, which wrote to
them, keeps them open (Fast DDS 2.14, ``SharedMemTransport::find_port``). The next child in the domain
takes the same id, finds those ports unhealthy, removes them and makes new ones; the kernel goes on
writing into the removed copy until its port watchdog gives up on it. What the kernel sent in between
is lost, and the newcomer's node reaches the kernel's graph at the next discovery heartbeat, 3 s later.
Measured with four kernels each starting and stopping (half of them killing) children beside two
busy loops: 63 of 906 shared-memory children were seen after 2.5 s or more (about 3 s each).

**How.** :func:`assign` gives each child started by the process layer a *slot*, 1 to 31, and points
its ``FASTRTPS_DEFAULT_PROFILES_FILE`` at the course's localhost profile with the port offsets of that
slot (:func:`.dds_config.slot_profile_env`): the child's first participant listens on the ports of
participant id ``slot``, a second one on the next, and so on; its participant ids stay Fast DDS's own,
so a child may still make several participants. The slot is the one given up longest ago among those
that no running child of this process holds and whose UDP ports no process has bound. A port is
reused only after every other free slot has been, not by the next child. The same test gave 0 of
191 such children at 2.5 s or more; ``benchmarks/discovery_after_crash.py`` measures a child started
right after a killed one: p90 0.16 s, against 3.17 s with Fast DDS's own choice.

Only the ports move: a child on a slot still announces itself to the discovery ports of participant
ids 0 to 31 on 127.0.0.1 (``PEER_IDS``), as every other participant does, listed port by port in its
profile (left to Fast DDS, the list would start at the slot's own offset and miss the ids below it),
from id 31 down to 0: the kernel, on id 0, is told last and so heard at once (:mod:`.dds_config`).

A child with a short lease (chapter 01) keeps its lease on its slot. A child whose environment names
another profile (UDP only, Fast DDS's defaults, the user's own) keeps it; so does a child outside the
LOCALHOST range.
"""

from __future__ import annotations

import errno
import socket
import threading
import time
from collections.abc import Callable
from typing import Any

from course_helpers.core import dds_config
from course_helpers.core.udp_sockets import discovery_port

SLOTS = range(1, dds_config.PEER_IDS)  # slot 0 is where Fast DDS's own choice starts (the kernel)

_lock = threading.Lock()
_released: dict[int, float] = {}  # slot -> when this process saw its last holder end (never: absent)
_holders: dict[int, Callable[[], bool]] = {}  # slot -> is its child still running?


def unicast_ports(domain_id: int, slot: int) -> tuple[int, int]:
    """The discovery and data ports of participant id ``slot`` in ``domain_id`` (RTPS's port mapping)."""
    discovery = discovery_port(domain_id, slot)
    return discovery, discovery + 1


def _ports_free(domain_id: int, slot: int) -> bool:
    """True if no process has bound the slot's UDP ports on 127.0.0.1 (a participant holds them)."""
    for port in unicast_ports(domain_id, slot):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind(("127.0.0.1", port))
            except OSError as exc:
                if exc.errno == errno.EADDRINUSE:
                    return False
                raise
    return True


def take(domain_id: int, running: Callable[[], bool]) -> int | None:
    """A free slot for a child whose process ``running()`` reports on, or None if every slot is taken.

    Free: no running child of this process holds it and no process has bound its ports. Of those, the
    one given up longest ago (never used counts as longest).
    """
    with _lock:
        now = time.monotonic()
        for slot, alive in list(_holders.items()):
            if not alive():
                del _holders[slot]
                _released[slot] = now
        for slot in sorted(SLOTS, key=lambda s: (_released.get(s, 0.0), s)):
            if slot not in _holders and _ports_free(domain_id, slot):
                _holders[slot] = running
                return slot
    return None


class Assignment:
    """A slot held for a child: from before it starts (:func:`assign`) until its process has ended."""

    def __init__(self):
        self._starting = True
        self._process = None

    def running(self) -> bool:
        return self._starting or (self._process is not None and self._process.poll() is None)

    def start(self, popen: Callable[[], Any]) -> Any:
        """Start the child with ``popen()`` (the process layer's ``subprocess.Popen``) and hold the slot
        for the process it returns; if the start fails, the slot is given back."""
        try:
            self._process = popen()
        finally:
            self._starting = False
        return self._process


def assign(env: dict[str, str], directory: str) -> Assignment:
    """Give the child about to start with ``env`` a slot, if it uses the course's localhost profile.

    Changes ``env`` in place (its profile), writing the slot's profile into ``directory`` (a folder
    private to this process). Start the child through :meth:`Assignment.start`.
    """
    assignment = Assignment()
    domain = env.get("ROS_DOMAIN_ID", "")
    lease_s = dds_config.slot_lease(env)
    if lease_s is not None and domain.isdigit():
        slot = take(int(domain), assignment.running)
        if slot is not None:
            env.update(dds_config.slot_profile_env(directory, slot, int(domain), lease_s))
    return assignment
