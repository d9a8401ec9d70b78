"""RTPS on the wire: capture a private network's traffic with ``dumpcap``, read it with ``tshark``.

Every DDS implementation speaks the same wire protocol, RTPS (OMG DDSI-RTPS): each UDP datagram
holds one RTPS message, a header naming the sender's GUID prefix and vendor, then submessages
such as DATA (a sample, or a discovery announcement), HEARTBEAT (a writer's "I have samples
first..last"), ACKNACK (a reader's "I have everything below base; send me these") and GAP (a
writer's "these numbers will never come"). Wireshark's RTPS dissector decodes all of them.

* :func:`start_capture` runs ``dumpcap`` inside a network namespace of the course
  (:mod:`.netns`) as a course child, on that namespace's loopback, where the course's processes
  talk; its file lives in the process layer's private folder. With ``dropped_group`` it also
  captures the netfilter log group that a firewall rule of the namespace sends the datagrams it
  drops to (``log group N queue-threshold 1 drop``): the loopback capture sees every datagram
  sent, before the input hook; the log says which of them never arrived.
* :meth:`Capture.stop` ends it without losing the last packets: dumpcap writes its file about once
  a second and drops what it has not read yet when it is stopped, so first a marker datagram (to
  UDP port 9, discard) is sent inside the namespace, and dumpcap is stopped only once the marker is
  in the file (in the drop log too: a rule of the capture's own logs and drops it there). Whatever
  the namespace carried before the marker is then in the file.
* :meth:`Capture.submessages` runs ``tshark`` over the file and turns its JSON (``-T json``, the
  dissector's tree; never its human text) into :class:`Submessage` records, one per submessage:
  time, ports, sender and destination GUID prefixes, kind, writer and reader entity ids,
  sequence numbers, the numbers an ACKNACK asks for or a GAP gives up, the endpoint a discovery
  announcement describes. A datagram that also appears in the drop log is matched to its copy on
  the loopback (same ports, same bytes; identical datagrams in order) and its records are marked
  ``dropped``.

``tshark`` prints a warning on its error output when run as root, so its JSON goes to a file of
its own (a shell redirects it) and the error output stays for messages.
Where the tools are missing, :func:`unavailable_reason` says so in one line, with the install.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import time
from collections import defaultdict, deque
from dataclasses import dataclass

from course_helpers.core import processes
from course_helpers.core.errors import CourseError
from course_helpers.core.waiting import poll_until

TOOLS = ("dumpcap", "tshark")
INSTALL = "sudo apt-get install tshark (Wireshark's command-line tools; dumpcap comes with them)"
GROUP = "capture"  # the process-layer group of the dumpcap children
READY_TEXT = "Capturing on"  # what dumpcap prints once it captures
READY_TIMEOUT_S = 10.0
MAX_FILE_KB = 200_000  # dumpcap stops by itself past this size (a guard; a lesson's capture is < 2 MB)
DISSECT_TIMEOUT_S = 120.0
MARKER_PORT = 9  # UDP discard: nothing listens; odd, so every capture filter of the course keeps it
MARKER_TIMEOUT_S = 15.0  # dumpcap writes about once a second; a busy machine may take longer
MARKER_PERIOD_S = 0.1  # s between looks into the file for the marker
MARKER_TABLE = "course_capture"  # the nftables table of the drop-log marker rule
SEND_MARKER = ("import socket, sys; socket.socket(socket.AF_INET, socket.SOCK_DGRAM)"
               f".sendto(sys.argv[1].encode(), ('127.0.0.1', {MARKER_PORT}))")
DROP_LOG_GROUP = 7  # the netfilter log group a lossy link reports its drops to (any unused number)
ODD_PORTS = "udp and udp[2:2] & 1 = 1"  # capture filter (BPF): UDP to an odd port, RTPS's user traffic
TSHARK_OPTIONS = ["-n", "-o", "udp.try_heuristic_first:TRUE"]  # RTPS is found by its 'RTPS' magic
# first: a port-based dissector (AFS uses 7000-7009) must not claim a datagram on such a port

# Submessage ids of DDSI-RTPS 2.5, section 9.4.5.1.1 (INFO_* ones change how the rest is read).
KINDS = {0x01: "PAD", 0x06: "ACKNACK", 0x07: "HEARTBEAT", 0x08: "GAP", 0x09: "INFO_TS", 0x0C: "INFO_SRC",
         0x0D: "INFO_REPLY_IP4", 0x0E: "INFO_DST", 0x0F: "INFO_REPLY", 0x12: "NACK_FRAG",
         0x13: "HEARTBEAT_FRAG", 0x15: "DATA", 0x16: "DATA_FRAG"}
RECORDED = {"DATA", "DATA_FRAG", "HEARTBEAT", "ACKNACK", "GAP", "NACK_FRAG", "HEARTBEAT_FRAG"}
# The built-in discovery writers' entity ids (DDSI-RTPS 2.5, table 9.2) and Wireshark's names
SPDP_WRITER = "000100c2"  # participants: DATA(p)
SEDP_PUBLICATIONS_WRITER = "000003c2"  # writers: DATA(w)
SEDP_SUBSCRIPTIONS_WRITER = "000004c2"  # readers: DATA(r)
DISCOVERY_NAMES = {SPDP_WRITER: "DATA(p)", SEDP_PUBLICATIONS_WRITER: "DATA(w)",
                   SEDP_SUBSCRIPTIONS_WRITER: "DATA(r)"}


def unavailable_reason() -> str | None:
    """None if dumpcap and tshark are installed; else one line naming what is missing and the install."""
    missing = [tool for tool in TOOLS if shutil.which(tool) is None]
    if missing:
        return f"{' and '.join(missing)} not found: {INSTALL}"
    return None


@dataclass(frozen=True)
class Submessage:
    """One RTPS submessage as captured.

    ``time`` is the capture's clock (s since the epoch); ``src``/``dst`` are GUID prefixes
    (24 hex digits; ``dst`` '' when the message names no destination); ``writer``/``reader``
    entity ids (8 hex digits). By kind: DATA/DATA_FRAG ``seq``; HEARTBEAT ``first``..``last``
    and ``count``; ACKNACK ``base`` (all below it acknowledged), ``numbers`` (the ones it asks
    for) and ``count``; GAP ``numbers`` (the ones it gives up). A discovery DATA(w)/DATA(r) has the
    ``endpoint`` GUID (32 hex digits) and ``topic`` it announces.
    """

    frame: int
    time: float
    dropped: bool
    src_port: int
    dst_port: int
    vendor: str
    src: str
    dst: str
    kind: str
    writer: str
    reader: str
    seq: int | None = None
    first: int | None = None
    last: int | None = None
    base: int | None = None
    numbers: tuple[int, ...] = ()
    count: int | None = None
    endpoint: str = ""
    topic: str = ""
    alive: bool = True

    @property
    def name(self) -> str:
        """Wireshark's name: DATA(p), DATA(w), DATA(r) for discovery ([UD] when leaving), else the kind."""
        if self.kind == "DATA" and self.writer in DISCOVERY_NAMES:
            name = DISCOVERY_NAMES[self.writer]
            return name if self.alive else name[:-1] + "[UD])"
        return self.kind

    @property
    def writer_guid(self) -> str:
        """The writer's full GUID (32 hex digits): the sender's for DATA, HEARTBEAT and GAP, the
        destination's for an ACKNACK or NACK_FRAG (a reader sends those to the writer)."""
        owner = self.dst if self.kind in ("ACKNACK", "NACK_FRAG") else self.src
        return owner + self.writer


class Capture:
    """A dumpcap child capturing into ``path``; :meth:`stop` it, then read :meth:`submessages`."""

    def __init__(self, namespace, path: str, child: processes.ChildProcess, dropped_group: int | None):
        self.namespace = namespace
        self.path = path
        self.child = child
        self.dropped_group = dropped_group
        self._read: dict[str, list[Submessage]] = {}

    @property
    def running(self) -> bool:
        """True while dumpcap captures."""
        return self.child.alive

    @property
    def size_bytes(self) -> int:
        """The capture file's size so far."""
        try:
            return os.path.getsize(self.path)
        except OSError:
            return 0

    def stop(self) -> str:
        """End the capture once everything sent before this call is in the file (see the module
        docstring); the file's path. Stopping twice is fine. Raises CourseError if the file never
        got the end marker (the capture is stopped all the same)."""
        try:
            if self.child.alive and self.namespace.alive:
                self._mark_end()
        finally:
            processes.stop([self.child.label], group=GROUP)
            self.child.stop()
            if self.dropped_group is not None and self.namespace.alive:  # the marker rule goes too
                self.namespace.run("nft", f"delete table inet {MARKER_TABLE}", check=False)
        return self.path

    def _mark_end(self) -> None:
        marker = f"course capture end {os.getpid()} {time.monotonic_ns()}"
        copies = 1 if self.dropped_group is None else 2  # the loopback's, and the drop log's
        self.namespace.run(sys.executable, "-c", SEND_MARKER, marker)
        found = poll_until(lambda: self._file_holds(marker.encode()) >= copies or not self.child.alive,
                           MARKER_TIMEOUT_S, period=MARKER_PERIOD_S, wake_on=None)
        if not found or self._file_holds(marker.encode()) < copies:
            raise CourseError(f"the capture's end marker did not reach {self.path} within "
                              f"{MARKER_TIMEOUT_S:g} s: its last packets may be missing. dumpcap said: "
                              f"{self.child.output_tail(300)}")

    def _file_holds(self, marker: bytes) -> int:
        try:
            with open(self.path, "rb") as handle:
                return handle.read().count(marker)
        except OSError:
            return 0

    def submessages(self, display_filter: str = "rtps") -> list[Submessage]:
        """Every RTPS submessage of the stopped capture that ``display_filter`` (Wireshark's display
        filter syntax) keeps, in capture order. Read once per filter."""
        if self.running:
            raise CourseError("stop the capture first (capture.stop()): dumpcap is still writing its file")
        if display_filter not in self._read:
            self._read[display_filter] = dissect(self.path, display_filter)
        return self._read[display_filter]

    def __repr__(self) -> str:
        state = "capturing" if self.running else "stopped"
        return f"<Capture {os.path.basename(self.path)} {state}, {self.size_bytes} bytes>"


def start_capture(namespace, label: str, capture_filter: str = "udp",
                  dropped_group: int | None = None) -> Capture:
    """Start dumpcap on the loopback of ``namespace`` (a :class:`~.netns.NetworkNamespace`).

    Args:
        label: names the child (group ``'capture'``) and the file; a capture of that label stops first.
        capture_filter: what to keep, in capture filter (BPF) syntax (``ODD_PORTS``: user traffic).
        dropped_group: also capture this netfilter log group, where a firewall rule of the namespace
            logs the datagrams it drops (the records of those datagrams come back ``dropped``).

    Returns once dumpcap captures. Raises CourseError (with the install line) without the tools.
    """
    reason = unavailable_reason()
    if reason is not None:
        raise CourseError(f"a capture needs Wireshark's tools: {reason}")
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in label)
    path = os.path.join(processes.log_dir(), f"{safe}.pcapng")
    processes.stop([label], group=GROUP)
    if os.path.exists(path):
        os.unlink(path)
    argv = ["dumpcap", "-q", "-i", "lo", "-f", capture_filter, "-a", f"filesize:{MAX_FILE_KB}"]
    if dropped_group is not None:
        argv += ["-i", f"nflog:{int(dropped_group)}"]
        table = f"inet {MARKER_TABLE}"  # runs before the namespace's other rules (priority -10)
        namespace.run("nft", f"add table {table}; flush table {table}; "
                             f"add chain {table} input {{ type filter hook input priority -10; }}; "
                             f"add rule {table} input udp dport {MARKER_PORT} "
                             f"log group {int(dropped_group)} queue-threshold 1 drop")
    child = namespace.start(label, processes.program_argv(*argv, "-w", path), group=GROUP, channel=False)
    poll_until(lambda: READY_TEXT in child.log() or not child.alive, READY_TIMEOUT_S)
    if not child.alive or READY_TEXT not in child.log():
        output = child.output_tail(600).strip()
        child.stop(grace_s=1.0)
        raise CourseError(f"dumpcap did not start capturing in network namespace {namespace.label!r}: "
                          f"{output or f'no word within {READY_TIMEOUT_S:g} s'}")
    return Capture(namespace, path, child, dropped_group)


def dissect(path: str, display_filter: str = "rtps") -> list[Submessage]:
    """The RTPS submessages of the capture file ``path`` (tshark's JSON, parsed), in capture order."""
    out = f"{path}.{os.getpid()}.json"
    argv = ["sh", "-c", 'out="$1"; shift; exec "$@" >"$out"', "sh", out,
            "tshark", "-r", path, *TSHARK_OPTIONS, "-Y", display_filter,
            "-T", "json", "--no-duplicate-keys", "-J", "frame udp rtps"]
    try:
        code, messages = processes.run(argv, timeout=DISSECT_TIMEOUT_S)
        if code != 0:
            raise CourseError(f"tshark could not read {path} (exit {code}): {messages.strip()[-600:]}")
        with open(out, encoding="utf-8") as handle:
            frames = json.load(handle)
    except (OSError, ValueError) as exc:
        raise CourseError(f"tshark's output for {path} could not be read: {exc}") from None
    finally:
        if os.path.exists(out):
            os.unlink(out)
    return records_of(frames)


# ---------------------------------------------------------------------- tshark's JSON
@dataclass
class _Datagram:
    number: int
    time: float
    on_log: bool  # a copy from the drop log, not from the loopback
    src_port: int
    dst_port: int
    payload: str
    rtps: list


def records_of(frames: list) -> list[Submessage]:
    """:class:`Submessage` records from tshark's ``-T json --no-duplicate-keys`` frames."""
    datagrams = []
    for frame in frames:
        layers = frame.get("_source", {}).get("layers", {})
        about = layers.get("frame", {})
        interface = about.get("frame.interface_id_tree", {}).get("frame.interface_name", "")
        udp = layers.get("udp", {})
        datagrams.append(_Datagram(
            number=int(about.get("frame.number", 0)), time=float(about.get("frame.time_epoch", 0.0)),
            on_log=interface.startswith("nflog"), src_port=int(udp.get("udp.srcport", 0)),
            dst_port=int(udp.get("udp.dstport", 0)), payload=str(udp.get("udp.payload", "")),
            rtps=_as_list(layers.get("rtps"))))
    dropped = _dropped_numbers(datagrams)
    records = []
    for datagram in datagrams:
        if not datagram.on_log:
            for message in datagram.rtps:
                records += _submessages(datagram, message, datagram.number in dropped)
    return records


def _dropped_numbers(datagrams: list[_Datagram]) -> set[int]:
    """The loopback frames whose datagram the drop log shows: same ports and bytes, in order."""
    sent: dict[tuple, deque] = defaultdict(deque)
    for datagram in datagrams:
        if not datagram.on_log:
            sent[(datagram.src_port, datagram.dst_port, datagram.payload)].append(datagram.number)
    dropped = set()
    for datagram in datagrams:
        if datagram.on_log:
            copies = sent[(datagram.src_port, datagram.dst_port, datagram.payload)]
            if not copies:
                raise CourseError(f"frame {datagram.number} of the drop log matches no datagram captured on "
                                  "the loopback: capture both with the same filter")
            dropped.add(copies.popleft())
    return dropped


def _submessages(datagram: _Datagram, message, dropped: bool) -> list[Submessage]:
    if not isinstance(message, dict):
        return []
    src = _prefix(message.get("rtps.guidPrefix.src"))
    vendor = str(message.get("rtps.vendorId", "")).removeprefix("0x")
    ids, trees = _as_list(message.get("rtps.sm.id")), _as_list(message.get("rtps.sm.id_tree"))
    if len(ids) != len(trees):
        raise CourseError(f"frame {datagram.number}: tshark listed {len(ids)} submessages and {len(trees)} "
                          "subtrees; this RTPS dissector's layout is not the one the course reads "
                          "(Wireshark 4)")
    dst, found = "", []
    for sm_id, tree in zip(ids, trees, strict=True):
        kind = KINDS.get(int(sm_id, 16), f"0x{int(sm_id, 16):02x}")
        tree = tree if isinstance(tree, dict) else {}
        if kind == "INFO_DST":
            dst = _prefix(tree.get("rtps.guidPrefix.dst"))
            dst = "" if set(dst) <= {"0"} else dst  # all zeros: every participant
        if kind not in RECORDED:
            continue
        found.append(Submessage(frame=datagram.number, time=datagram.time, dropped=dropped,
                                src_port=datagram.src_port, dst_port=datagram.dst_port, vendor=vendor,
                                src=src, dst=dst, kind=kind, **_fields(kind, tree)))
    return found


def _fields(kind: str, tree: dict) -> dict:
    little = tree.get("rtps.sm.flags_tree", {}).get("rtps.flag.endianness") == "1"
    seqs = [int(s) for s in _as_list(tree.get("rtps.sm.seqNumber"))]
    fields = {"writer": _entity(tree.get("rtps.sm.wrEntityId")),
              "reader": _entity(tree.get("rtps.sm.rdEntityId"))}
    if kind in ("DATA", "DATA_FRAG"):
        fields["seq"] = seqs[0] if seqs else None
        fields["endpoint"] = _prefix(_find(tree, "rtps.param.endpoint_guid"))
        fields["topic"] = str(_find(tree, "rtps.param.topicName") or "")
        status = _find(tree, "rtps.param.status_info")  # PID_STATUS_INFO: 1 disposed, 2 unregistered
        fields["alive"] = not (status and int(str(status), 16) & 0x3)
    elif kind == "HEARTBEAT" and len(seqs) >= 2:
        fields.update(first=seqs[0], last=seqs[1], count=_int(tree.get("rtps.heartbeat_count")))
    elif kind in ("ACKNACK", "GAP"):
        base, numbers = _bitmap(_subtree_with(tree, "rtps.bitmap.num_bits"), little)
        if kind == "ACKNACK":
            fields.update(base=base, numbers=numbers, count=_int(tree.get("rtps.acknack.count")))
        elif seqs and base is not None:  # gapStart..gapList.base-1, then the gapList's bits
            fields.update(base=base, numbers=tuple(range(seqs[0], base)) + numbers)
    return fields


def _bitmap(tree: dict | None, little: bool) -> tuple[int | None, tuple[int, ...]]:
    """A SequenceNumberSet: (bitmapBase, the numbers whose bit is set). Bit i of the set, counted from
    the most significant bit of the first 32-bit word (in the submessage's byte order), is base + i."""
    if not tree:
        return None, ()
    base = int(_as_list(tree.get("rtps.sm.seqNumber"))[0])
    bits = int(tree.get("rtps.bitmap.num_bits", 0))
    raw = bytes.fromhex(str(tree.get("rtps.bitmap", "")).replace(":", ""))
    words = [int.from_bytes(raw[i:i + 4], "little" if little else "big") for i in range(0, len(raw), 4)]
    return base, tuple(base + i for i in range(min(bits, 32 * len(words)))
                       if words[i // 32] >> (31 - i % 32) & 1)


def _as_list(value) -> list:
    if value is None:
        return []
    return value if isinstance(value, list) else [value]


def _int(value) -> int | None:
    return int(value) if value not in (None, "") else None


def _prefix(value) -> str:
    return str(value or "").replace(":", "").lower()


def _entity(value) -> str:
    return str(value or "").lower().removeprefix("0x").zfill(8) if value else ""


def _find(tree, key: str):
    """The first value of ``key`` anywhere below ``tree`` (depth first), or None."""
    if isinstance(tree, dict):
        if key in tree:
            return _as_list(tree[key])[0]
        children = tree.values()
    elif isinstance(tree, list):
        children = tree
    else:
        return None
    for child in children:
        found = _find(child, key)
        if found is not None:
            return found
    return None


def _subtree_with(tree: dict, key: str) -> dict | None:
    """The first dict below ``tree`` (itself excluded) that holds ``key`` (a SequenceNumberSet)."""
    for child in tree.values():
        if isinstance(child, dict):
            if key in child:
                return child
            found = _subtree_with(child, key)
            if found is not None:
                return found
    return None
